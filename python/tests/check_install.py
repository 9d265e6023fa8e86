#!/usr/bin/python3
"""pip install from the checkout, as a user does it without PyPI: a venv over Debian's site packages,
--no-build-isolation --no-index. Works on a copy of python/ and proto/ so the checkout gets no build files.
Usage: check_install.py SOURCE_DIR BIN_DIR WORK_DIR. Prints 'N passed, N failed'."""
import os
import shutil
import subprocess
import sys

src, bin_dir, work = sys.argv[1:4]
shutil.rmtree(work, ignore_errors=True)
os.makedirs(work)
for d in ("python", "proto"):
    shutil.copytree(os.path.join(src, d), os.path.join(work, "src", d),
                    ignore=shutil.ignore_patterns("build", "*.egg-info", "__pycache__"))
env_dir = os.path.join(work, "env")
subprocess.run(["/usr/bin/python3", "-m", "venv", "--system-site-packages", env_dir], check=True)
py = os.path.join(env_dir, "bin", "python")
subprocess.run([py, "-m", "pip", "install", "-q", "--no-build-isolation", "--no-index",
                os.path.join(work, "src", "python")], check=True)

env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VALVEBENCH_SERVER")}
env.update(VALVEBENCH_BIN_DIR=bin_dir, VALVEBENCH_DB=os.path.join(work, "local.db"))
passed = failed = 0


def check(name, code, expect):
    global passed, failed
    proc = subprocess.run([py, "-c", code], cwd=work, env=env, capture_output=True, text=True)
    if proc.returncode == 0 and expect in proc.stdout:
        passed += 1
    else:
        failed += 1
        print("FAIL %s: rc %d\n%s%s" % (name, proc.returncode, proc.stdout, proc.stderr[-3000:]))


site = os.path.join(env_dir, "lib")
check("imported from the venv, not the checkout",
      "import valvebench; print(valvebench.__file__)", site)
check("stubs generated at install", "from valvebench.v1 import api_pb2_grpc, spec_pb2; print('stubs ok')", "stubs ok")
check("pytest plugin entry point",
      "import importlib.metadata as m; print([e.value for e in m.entry_points(group='pytest11')])",
      "valvebench.pytest_plugin")
check("local run through the installed package",
      "import valvebench\nwith valvebench.Client() as c:\n"
      "    r = c.run(%r)[0]\n    print(r.status, len(r.trace()))" % os.path.join(src, "examples", "standard", "e1.json"),
      "done")
proc = subprocess.run([py, "-m", "pytest", "--help"], cwd=work, env=env, capture_output=True, text=True)
if "--valvebench-server" in proc.stdout:
    passed += 1
else:
    failed += 1
    print("FAIL pytest loads the plugin by itself:\n" + proc.stdout[-2000:] + proc.stderr[-2000:])
print("%d passed, %d failed" % (passed, failed))
sys.exit(1 if failed else 0)
