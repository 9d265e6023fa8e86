"""Controller checks as a CI suite, with the valvebench pytest plugin (docs/python.md "pytest plugin").

    PYTHONPATH=build/python /usr/bin/python3 -m pytest -p valvebench.pytest_plugin examples/pytest \
        --junitxml=laws.xml                                  # embedded emulator, runs in the local store
    ... --valvebench-server 127.0.0.1:50051                  # or on a bench server (token: $VALVEBENCH_TOKEN)

Each run's id lands in the JUnit XML (property valvebench_run), so a red CI job names the stored run to
inspect: benchctl show ID, benchctl export ID --hdf5 run.h5.
"""
import os

import pytest

SPEC = os.path.join(os.path.dirname(__file__), "..", "compare-current-controllers.json")


@pytest.fixture(scope="module")
def laws(valvebench_client):
    """The four current laws once for the module (the fixture's client: emulator or --valvebench-server)."""
    return valvebench_client.run(SPEC).raise_for_status()


@pytest.mark.parametrize("law", ["hysteresis", "pi", "predictive", "fuzzy"])
def test_law_holds_half_an_ampere(bench, laws, law):
    run = laws[law]
    bench.record(run)
    bench.check(run, "mean_current_A", near=0.5, abs=0.005)   # A, over the hold (20-100 ms)
    bench.check(run, "rmse", below=0.01)                       # A


def test_pi_at_reduced_supply(bench):
    # The same task at 18 V: PI still holds 0.5 A (13 ohm x 0.5 A = 6.5 V needed).
    batch = bench.run(SPEC, overrides={"conditions": {"supply_V": 18.0}, "variants": []})
    run = batch[0]
    assert run.spec["conditions"]["supply_V"] == 18.0
    bench.check(run, "mean_current_A", near=0.5, abs=0.01)
