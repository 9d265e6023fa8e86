"""Units of trace channels and metrics. Names carry their SI unit as a suffix (``i_A``, ``t_s``,
``flow_kg_per_s``); the few that cannot (``ref``, ``rmse``, ...) take the unit of the controlled variable: A for
current laws, m for position laws. The HDF5/MAT export (export/units.cc) uses the same table; a test checks
that both agree for every channel."""

import math

POSITION_LAWS = ("cascade_pi_position", "sliding_mode_position")
# Laws without a reference: tracking metrics and the ref channel are NaN.
OPEN_LOOP_LAWS = ("open_loop_pwm", "dither_pwm")

CHANNEL_UNITS = {
    "t_s": "s", "gate": "1", "v_coil_V": "V", "i_A": "A", "x_m": "m", "v_mps": "m/s", "x_avg_m": "m",
    "flow_kg_per_s": "kg/s", "v2_int_V2s": "V^2 s", "energy_int_J": "J", "switch_count": "1",
}
_SUFFIX_UNITS = (("_kg_per_s", "kg/s"), ("_mps", "m/s"), ("_V2s", "V^2 s"), ("_pct", "%"), ("_Pa", "Pa"),
                 ("_Hz", "Hz"), ("_J", "J"), ("_W", "W"), ("_V", "V"), ("_A", "A"), ("_m", "m"), ("_s", "s"))


def controlled_unit(controller):
    """'A' or 'm' for a law name (pi_current, sliding_mode_position, ...); '' when the law has no reference."""
    if controller in POSITION_LAWS:
        return "m"
    if controller in OPEN_LOOP_LAWS or not controller:
        return ""
    return "A"


def channel_unit(channel, controller=""):
    if channel in CHANNEL_UNITS:
        return CHANNEL_UNITS[channel]
    if channel == "ref":
        return controlled_unit(controller)
    for suffix, unit in _SUFFIX_UNITS:
        if channel.endswith(suffix):
            return unit
    return ""


def channel_column(channel, controller=""):
    """The DataFrame column of a channel: its name, which carries its unit; ``ref`` becomes ``ref_A``/``ref_m``."""
    if channel == "ref":
        unit = controlled_unit(controller)
        return "ref_" + unit if unit else "ref"
    return channel


_METRIC_UNITS = {"overshoot": "1", "switches": "1", "effort_l2": "V s^0.5", "effort_rms": "V",
                 "effort_u_l2": "N s^0.5", "pwm_duty": "1"}


def metric_unit(metric, controller=""):
    y = controlled_unit(controller) or "A"
    if metric in ("rmse", "max_abs_error"):
        return y
    if metric == "iae":
        return y + " s"
    if metric in _METRIC_UNITS:
        return _METRIC_UNITS[metric]
    return channel_unit(metric)


def metric_column(metric, controller=""):
    """A metric's DataFrame column with its unit in the name: rmse -> rmse_A, iae -> iae_A_s,
    effort_l2 -> effort_l2_V_sqrt_s; names that already end in a unit, and ratios/counts, stay as they are."""
    y = controlled_unit(controller) or "A"
    if metric in ("rmse", "max_abs_error"):
        return metric + "_" + y
    if metric == "iae":
        return metric + "_" + y + "_s"
    if metric == "effort_l2":
        return "effort_l2_V_sqrt_s"
    if metric == "effort_rms":
        return "effort_rms_V"
    if metric == "effort_u_l2":
        return "effort_u_l2_N_sqrt_s"
    return metric


# SI prefixes, largest first (common/units.h UnitPrefixes).
_PREFIXES = (("G", 1e-9), ("M", 1e-6), ("k", 1e-3), ("", 1.0), ("m", 1e3), ("\u00b5", 1e6), ("n", 1e9), ("p", 1e12))
_UNPREFIXED = ("", "1", "%", "turns", "count", "K")


def choose_unit(max_abs, unit):
    """(prefixed unit, scale) for values of largest magnitude max_abs in SI `unit`: the rule of common/units.h
    and web/static/format.js. The prefix goes on the first factor raised to its power (m^2 -> mm^2 is 1e6);
    the kilogram is a prefixed gram (kg -> g, mg; kg/s -> mg/s)."""
    if unit in _UNPREFIXED or unit[:1].isdigit() or unit[:1] == ".":
        return unit, 1.0
    end = min([unit.find(c) for c in " /*" if c in unit] or [len(unit)])
    head, rest, power = unit[:end], unit[end:], 1.0
    if "^" in head:
        caret = head.index("^")
        power = float(head[caret + 1:])
        rest = head[caret:] + rest
        head = head[:caret]
    to_base = 1.0
    if head == "kg":
        head, to_base = "g", 1e3 ** power
    pick = ("k", 1e-3) if to_base != 1.0 else ("", 1.0)
    if max_abs > 0 and math.isfinite(max_abs):
        pick = _PREFIXES[-1]
        for p in _PREFIXES:
            if max_abs * to_base * p[1] ** power >= 1 - 1e-12:
                pick = p
                break
    return pick[0] + head + rest, to_base * pick[1] ** power


def format_quantity(value, unit):
    """'953.3 \u00b5A', '81.13 mm^2', '27.73 g', '-' for NaN: benchctl's and the web page's writing of a value."""
    if value is None or not math.isfinite(value):
        return "-"
    shown, scale = choose_unit(abs(value), unit)
    suffix = "" if shown in ("", "1") else " " + shown
    if value == 0:
        return "0" + suffix
    x = value * scale
    if x == round(x) and abs(x) < 1e9:
        return "%d%s" % (round(x), suffix)
    return "%s%s" % (("%.4g" % x), suffix)
