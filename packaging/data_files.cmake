# Which files of examples/ and docs/ the install tree and the Debian package take (issue 41): a whitelist of the
# kinds of file these folders are written in, so nothing a checkout happens to hold enters the package: not the
# bytecode a Python run leaves (__pycache__/, *.pyc), not an editor's backup or lock (*~, .*.swp, .#name), not a
# notebook's checkpoints, not a local store (*.db). A new kind of file in examples/ or docs/ is added here;
# packaging/data_files_test.cmake checks the list against decoys of every kind above.
set(VB_DATA_FILE_PATTERNS
    FILES_MATCHING
    PATTERN "*.json" PATTERN "*.md" PATTERN "*.py" PATTERN "*.ipynb" PATTERN "*.sh" PATTERN "*.png"
    PATTERN "*.svg" PATTERN "*.csv"
    # Hidden files and folders (editor locks and swap files, .ipynb_checkpoints) and caches are never data,
    # whatever their suffix says.
    PATTERN ".*" EXCLUDE
    PATTERN "__pycache__" EXCLUDE
    PATTERN "*.pyc" EXCLUDE
    PATTERN "*~" EXCLUDE)
