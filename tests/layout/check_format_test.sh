#!/bin/bash
# The format check of changed lines (scripts/check_format.sh) must report a badly formatted changed line and nothing
# else: in a temporary git repository holding the repository's .clang-format and a committed, formatted file,
#   (a) a changed line badly formatted    -> exit 1, the file named, the fixing command printed;
#   (b) a changed line well formatted     -> exit 0;
#   (c) a badly formatted line NOT changed (same file, another line changed) -> exit 0, not reported;
#   (d) a bad argument -> exit 2;  (e) clang-format not on PATH -> exit 2 naming the Debian package clang-format;
#   (f) without git-clang-format (the clang-format-diff fallback), (a) and (c) again.
# Usage: check_format_test.sh SOURCE_ROOT. Exit 0 when every case holds, 1 otherwise (one line per failed case).
set -u
src=${1:?usage: check_format_test.sh SOURCE_ROOT}
src=$(cd "$src" && pwd) || exit 1
checker=$src/scripts/check_format.sh
if [[ ! -f $checker || ! -f $src/.clang-format ]]; then
  echo "FAIL: no scripts/check_format.sh or .clang-format in $src"
  exit 1
fi
if ! command -v clang-format >/dev/null; then
  echo "FAIL: clang-format is not installed (Debian package clang-format; scripts/setup.sh installs it)"
  exit 1
fi

# The temporary repository ignores the user's and the system's git configuration (hooks, templates, signing).
unset GIT_DIR GIT_WORK_TREE GIT_INDEX_FILE
export GIT_CONFIG_GLOBAL=/dev/null GIT_CONFIG_NOSYSTEM=1
tmp=$(mktemp -d) || exit 1
trap 'rm -rf "$tmp"' EXIT
repo=$tmp/repo
mkdir "$repo" && cd "$repo" || exit 1
git init -q -b main . && git config user.name check_format_test && git config user.email check_format_test@localhost &&
  git config commit.gpgsign false || exit 1
cp "$src/.clang-format" .
failures=0
fail() {
  echo "FAIL: $*"
  failures=$((failures + 1))
}

# The formatted file every case starts from (line 10 is the one the cases change).
write_good() {
  cat >shape.cpp <<'EOF'
// Fixture of check_format_test.sh: formatted as .clang-format says.
#include <vector>

namespace fixture {

int add(int a, int b) { return a + b; }

int scale(int v) {
  const int factor = 2;
  return v * factor;
}

int total(const std::vector<int>& values) {
  int sum = 0;
  for (int v : values) sum += v;
  return sum;
}

}  // namespace fixture
EOF
}
commit() {
  git add shape.cpp .clang-format && git commit -q --allow-empty -m "$1" || exit 1
  git rev-parse HEAD
}
# restart: back to the formatted fixture, committed; prints the commit id (the BASE of the next case).
restart() {
  write_good
  commit "formatted fixture again"
}
# run_checker OUTFILE [BASE]: the checker from inside the temporary repository; prints its exit status.
run_checker() {
  local out=$1
  shift
  "$BASH" "$checker" "$@" >"$out" 2>&1
  echo $?
}
# set_line N TEXT: replaces line N of shape.cpp.
set_line() {
  local n=$1 text=$2 i=0 line
  local -a lines=()
  while IFS= read -r line; do
    i=$((i + 1))
    if ((i == n)); then lines+=("$text"); else lines+=("$line"); fi
  done <shape.cpp
  printf '%s\n' "${lines[@]}" >shape.cpp
}

write_good
clang-format --style=file --dry-run --Werror shape.cpp 2>/dev/null || fail "the fixture is not formatted (fix the test)"
first=$(commit "formatted fixture")

# (a) a changed line badly formatted, committed: the default BASE (HEAD~1; there is no origin/main here) -> 1.
set_line 10 '  return   v*factor ;'
commit "bad change" >/dev/null
rc=$(run_checker "$tmp/a.out")
[[ $rc == 1 ]] || fail "(a) a badly formatted changed line: exit $rc, expected 1; output: $(cat "$tmp/a.out")"
grep -q 'shape\.cpp' "$tmp/a.out" || fail "(a) the output does not name shape.cpp: $(cat "$tmp/a.out")"
grep -q 'git clang-format' "$tmp/a.out" || fail "(a) the output does not give the fixing command: $(cat "$tmp/a.out")"
grep -q 'return v \* factor;' "$tmp/a.out" || fail "(a) the output does not show the formatted line:" \
  "$(cat "$tmp/a.out")"
# The same change not yet committed, against an explicit commit id -> 1.
base=$(restart)
set_line 10 '  return   v*factor ;'
rc=$(run_checker "$tmp/a2.out" "$base")
[[ $rc == 1 ]] || fail "(a) an uncommitted badly formatted line against $base: exit $rc, expected 1"
grep -q 'shape\.cpp' "$tmp/a2.out" || fail "(a) uncommitted: the output does not name shape.cpp"

# (b) a changed line well formatted (uncommitted, explicit BASE) -> 0.
base=$(restart)
set_line 10 '  return v * factor + 1;'
rc=$(run_checker "$tmp/b.out" "$base")
[[ $rc == 0 ]] || fail "(b) a well formatted changed line: exit $rc, expected 0; output: $(cat "$tmp/b.out")"

# (c) a badly formatted line committed in the BASE stays unreported when another line of the same file changes.
base=$(restart)
set_line 6 'int add(int a,int b){return a+b;}'
clang-format --style=file --dry-run --Werror shape.cpp 2>/dev/null &&
  fail "(c) the planted line is formatted (fix the test)"
old_bad=$(commit "badly formatted line, before BASE")
set_line 15 '  for (int v : values) sum += 2 * v;'
commit "formatted change after it" >/dev/null
rc=$(run_checker "$tmp/c.out" "$old_bad")
[[ $rc == 0 ]] || fail "(c) an unchanged badly formatted line was reported: exit $rc, expected 0; output:" \
  "$(cat "$tmp/c.out")"
grep -q 'a+b' "$tmp/c.out" && fail "(c) the output shows the unchanged line: $(cat "$tmp/c.out")"
# ... while since the commit before it (the line is then a changed one) it is reported -> 1.
rc=$(run_checker "$tmp/c2.out" "$base")
[[ $rc == 1 ]] || fail "(c) the same line, changed since $base: exit $rc, expected 1"

# (d) bad arguments -> 2 with a message.
rc=$(run_checker "$tmp/d.out" no-such-commit)
[[ $rc == 2 ]] || fail "(d) BASE no-such-commit: exit $rc, expected 2"
grep -q 'no-such-commit' "$tmp/d.out" || fail "(d) the message does not name the bad BASE: $(cat "$tmp/d.out")"
rc=$(run_checker "$tmp/d2.out" --no-such-option)
[[ $rc == 2 ]] || fail "(d) --no-such-option: exit $rc, expected 2"
rc=$(run_checker "$tmp/d3.out" HEAD HEAD~1)
[[ $rc == 2 ]] || fail "(d) two arguments: exit $rc, expected 2"
rc=$(run_checker "$tmp/d4.out" --help)
if [[ $rc != 0 ]] || ! grep -q 'Usage' "$tmp/d4.out"; then fail "(d) --help: exit $rc or no usage"; fi

# (e) clang-format missing: a PATH holding git only -> 2 naming the Debian package.
mkdir "$tmp/bin" && ln -s "$(command -v git)" "$tmp/bin/git"
out=$(PATH=$tmp/bin "$BASH" "$checker" "$first" 2>&1)
rc=$?
[[ $rc == 2 ]] || fail "(e) without clang-format: exit $rc, expected 2; output: $out"
[[ $out == *'Debian package clang-format'* ]] || fail "(e) without clang-format, the message does not name the" \
  "Debian package clang-format: $out"

# (f) the fallback without git-clang-format (clang-format-diff, same package): a PATH without it, (a) and (c) again.
python=/usr/bin/python3  # the system one (a python3 found on PATH may be a wrapper needing more of PATH)
[[ -x $python ]] || python=$(command -v python3)
if command -v clang-format-diff >/dev/null && [[ -n $python ]]; then
  mkdir "$tmp/bin2"
  for t in git clang-format clang-format-diff; do ln -s "$(command -v "$t")" "$tmp/bin2/$t"; done
  ln -s "$python" "$tmp/bin2/python3"
  base=$(restart)
  set_line 10 '  return   v*factor ;'
  out=$(PATH=$tmp/bin2 "$BASH" "$checker" "$base" 2>&1)
  rc=$?
  [[ $rc == 1 && $out == *shape.cpp* ]] || fail "(f) clang-format-diff, a badly formatted changed line: exit $rc," \
    "expected 1 naming shape.cpp; output: $out"
  set_line 6 'int add(int a,int b){return a+b;}'
  base=$(commit "badly formatted line, before BASE")
  set_line 15 '  for (int v : values) sum += 2 * v;'
  out=$(PATH=$tmp/bin2 "$BASH" "$checker" "$base" 2>&1)
  rc=$?
  [[ $rc == 0 ]] || fail "(f) clang-format-diff, an unchanged badly formatted line: exit $rc, expected 0; output: $out"
else
  echo "check_format_test: no clang-format-diff or python3: the fallback (f) is not tested"
fi

if ((failures > 0)); then
  echo "check_format_test: $failures failure(s)"
  exit 1
fi
echo "check_format_test: all cases hold"
