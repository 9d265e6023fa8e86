"""The pytest plugin as a CI job uses it: examples/pytest on the embedded emulator, JUnit XML with the run ids,
and a failing check that names the run, its metric with the unit and the bound."""
import os
import subprocess
import sys
import xml.etree.ElementTree as ET

import valvebench


def pytest_run(args, cwd, db):
    package_parent = os.path.dirname(os.path.dirname(os.path.abspath(valvebench.__file__)))
    env = dict(os.environ, VALVEBENCH_DB=db,
               PYTHONPATH=os.pathsep.join([package_parent] + os.environ.get("PYTHONPATH", "").split(os.pathsep)))
    return subprocess.run([sys.executable, "-m", "pytest", "-p", "valvebench.pytest_plugin", "-p", "no:cacheprovider",
                           "-q"] + args, cwd=cwd, env=env, capture_output=True, text=True)


def properties(xml_path):
    out = {}
    for case in ET.parse(xml_path).getroot().iter("testcase"):
        out[case.get("name")] = [(p.get("name"), p.get("value")) for p in case.iter("property")]
    return out


def test_example_suite_passes_and_names_its_runs(repo, tmp_path):
    xml = tmp_path / "laws.xml"
    db = str(tmp_path / "store.db")
    proc = pytest_run([os.path.join(repo, "examples", "pytest"), "--junitxml", str(xml), "--valvebench-db", db],
                      tmp_path, db)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "5 passed" in proc.stdout
    props = properties(xml)
    assert len(props) == 5
    for name, p in props.items():
        runs = [v for k, v in p if k == "valvebench_run"]
        assert runs, name
        assert all(("local store " + db) in v and " done " in v for v in runs), runs
    # The ids are the stored runs': the Python client finds them in the same store.
    rid = int([v for k, v in props["test_law_holds_half_an_ampere[pi]"] if k == "valvebench_run"][0].split()[0])
    with valvebench.Client.local(db=db) as c:
        assert c.get_run(rid).name == "compare-current-controllers/pi"


def test_failing_check_names_the_run_metric_unit_and_bound(repo, tmp_path):
    spec = os.path.join(repo, "examples", "standard", "e1.json")
    (tmp_path / "test_strict.py").write_text(
        "def test_too_strict(bench):\n"
        "    run = bench.run(%r)[0]\n"
        "    bench.check(run, 'mean_current_A', below=1e-9)\n" % spec)
    xml = tmp_path / "strict.xml"
    db = str(tmp_path / "store.db")
    proc = pytest_run(["test_strict.py", "--junitxml", str(xml), "--valvebench-db", db], tmp_path, db)
    assert proc.returncode == 1, proc.stdout
    out = proc.stdout
    assert "mean_current_A = " in out and " A, expected <= 1e-09 A" in out, out
    assert "valvebench runs" in out and "valvebench_run = 1 e1 done" in out, out
    failure = ET.parse(xml).getroot().find(".//testcase/failure")
    assert "run 1 (e1) in local store" in failure.get("message"), failure.get("message")


def test_example_suite_on_a_server_given_on_the_command_line(repo, remote_server, tmp_path):
    from conftest import OPERATOR
    xml = tmp_path / "remote.xml"
    proc = pytest_run([os.path.join(repo, "examples", "pytest"), "--junitxml", str(xml),
                       "--valvebench-server", remote_server, "--valvebench-token", OPERATOR],
                      tmp_path, str(tmp_path / "unused.db"))
    assert proc.returncode == 0, proc.stdout + proc.stderr
    runs = [v for p in properties(xml).values() for k, v in p if k == "valvebench_run"]
    assert len(runs) == 5 and all(v.endswith("(server %s)" % remote_server) for v in runs), runs
    assert not os.path.exists(tmp_path / "unused.db")
