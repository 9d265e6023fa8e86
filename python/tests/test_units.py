"""The one unit rule (common/units.h, web/static/format.js) in Python: the same figure written the same way as
`benchctl show` and the web's run page write it (issue 37)."""

import math

from valvebench import units


def test_compound_units_are_prefixed_on_their_first_factor():
    assert units.format_quantity(81.13e-6, "m^2") == "81.13 mm^2"   # not 81.13 um^2
    assert units.format_quantity(0.02773, "kg") == "27.73 g"        # not 27.73 mkg
    assert units.format_quantity(7.514e-4, "kg/s") == "751.4 mg/s"  # not 751.4 ukg/s
    assert units.format_quantity(9.533e-4, "A") == "953.3 \u00b5A"
    assert units.format_quantity(8.67476e-05, "W") == "86.75 \u00b5W"
    assert units.format_quantity(2e-3, "N s/m") == "2 mN s/m"
    assert units.format_quantity(0.0, "kg") == "0 kg"
    assert units.format_quantity(1234, "1") == "1234"
    assert units.format_quantity(math.nan, "A") == "-"


def test_every_metric_has_a_unit_and_a_unit_suffixed_column():
    for law in ("pi_current", "cascade_pi_position"):
        for metric in ("rmse", "iae", "max_abs_error", "effort_l2", "effort_rms", "effort_u_l2", "energy_J",
                       "mean_current_A", "mean_flow_kg_per_s", "switching_rate_Hz", "driver_loss_W"):
            assert units.metric_unit(metric, law), metric
            assert "_" in units.metric_column(metric, law), metric
