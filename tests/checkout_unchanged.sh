#!/bin/sh
# The suite never writes into the checkout (issue 41): CTest runs `snapshot` before every test (fixture setup)
# and `check` after all of them (fixture cleanup). The state is git's view of the tree outside the build folder,
# ignored files included (a __pycache__/ is ignored by .gitignore but would still enter the package), with a hash
# of every file git lists, so a file that was already dirty and is written again is caught too. Other build trees
# (`build-*/`, as .gitignore names them: scripts/fuzz.sh's build-fuzz/, a sanitizer build) are left out with it:
# they are written by builds, not by tests, and may be busy while the suite runs.
#   checkout_unchanged.sh snapshot|check SOURCE_DIR BINARY_DIR STATE_FILE
# Exit 0 when unchanged, 1 naming the files that changed, 77 (skipped) when SOURCE_DIR is not a git checkout.
set -eu
mode=$1 src=$2 bin=$3 state=$4
if ! git -C "$src" rev-parse --is-inside-work-tree >/dev/null 2>&1; then
  echo "not a git checkout ($src): nothing to compare"; exit 77
fi
top=$(git -C "$src" rev-parse --show-toplevel)
bin=$(cd "$bin" && pwd -P)
case "$bin/" in
  "$top"/*) exclude=":(exclude)${bin#"$top"/}" ;;
  *) exclude=":(exclude).git" ;;
esac
listing() {
  git -C "$top" status --porcelain --ignored --untracked-files=all -- . "$exclude" ":(exclude)build-*" |
  LC_ALL=C sort |
  while IFS= read -r line; do
    path=${line#???}
    case "$path" in *" -> "*) path=${path#*" -> "} ;; esac
    if [ -f "$top/$path" ]; then
      echo "$line $(sha256sum <"$top/$path" | cut -c1-16)"
    else
      echo "$line"
    fi
  done
}
case "$mode" in
  snapshot)
    mkdir -p "$(dirname "$state")"
    listing >"$state"
    echo "checkout state recorded: $(wc -l <"$state") entries outside $bin" ;;
  check)
    [ -f "$state" ] || { echo "no snapshot at $state (the fixture's setup did not run)"; exit 1; }
    listing >"$state.after"
    if diff -u "$state" "$state.after" >"$state.diff"; then
      echo "1 passed, 0 failed: the checkout outside the build folder is as it was before the tests"
    else
      echo "The tests changed the checkout outside the build folder (a test must write only into the build tree"
      echo "or a temp folder). Before -> after, git status --porcelain --ignored with file hashes:"
      grep -E '^[-+][^-+]' "$state.diff"
      echo "0 passed, 1 failed"
      exit 1
    fi ;;
  *) echo "usage: $0 snapshot|check SOURCE_DIR BINARY_DIR STATE_FILE" >&2; exit 2 ;;
esac
