#!/usr/bin/python3
"""Executes every notebook of a folder headless (Debian's jupyter-nbconvert, the python3 kernel) on a fresh
local store; a cell that raises fails the notebook. Usage: run_notebooks.py NOTEBOOK_DIR OUT_DIR
(PYTHONPATH must reach the valvebench package, e.g. build/python). Prints 'N passed, N failed'."""
import glob
import os
import shutil
import subprocess
import sys
import time

nb_dir, out_dir = sys.argv[1:3]
shutil.rmtree(out_dir, ignore_errors=True)
os.makedirs(out_dir)
env = dict(os.environ, VALVEBENCH_DB=os.path.join(out_dir, "local.db"), MPLBACKEND="Agg",
           PYDEVD_DISABLE_FILE_VALIDATION="1")
env.pop("VALVEBENCH_SERVER", None)  # the embedded emulator, whatever the caller's shell says
passed = failed = 0
for nb in sorted(glob.glob(os.path.join(nb_dir, "*.ipynb"))):
    t0 = time.monotonic()
    proc = subprocess.run(["jupyter-nbconvert", "--to", "notebook", "--execute", "--output-dir", out_dir,
                           "--ExecutePreprocessor.timeout=300", nb], env=env, capture_output=True, text=True)
    took = time.monotonic() - t0
    if proc.returncode == 0:
        passed += 1
        print("ok   %s (%.1f s)" % (os.path.basename(nb), took))
    else:
        failed += 1
        print("FAIL %s (%.1f s)\n%s" % (os.path.basename(nb), took, proc.stderr[-4000:]))
print("%d passed, %d failed" % (passed, failed))
sys.exit(1 if failed or not passed else 0)
