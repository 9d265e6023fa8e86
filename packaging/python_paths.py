# Installed by CMake: where the installed programs are (valvebench.local.find_tool). This file is
# <prefix>/lib/python3/dist-packages/valvebench/_build_paths.py, the programs are in <prefix>/bin.
import os

BIN_DIR = os.path.normpath(os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "..", "..", "bin"))
SOURCE_DIR = ""
