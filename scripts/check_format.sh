#!/bin/bash
# Checks that the C++ lines changed since BASE are formatted as .clang-format says (only the changed lines of *.h and
# *.cpp files, never whole files: most of the code predates the formatter). Run it from inside the work tree (else
# the repository holding this script is checked).
usage() {
  cat <<'EOF'
Usage: scripts/check_format.sh [BASE]
       scripts/check_format.sh --help

Checks that the lines of *.h and *.cpp files changed since BASE (committed since BASE, staged or not yet staged;
untracked files are not looked at) are formatted as the repository's .clang-format says. Lines nobody changed are
never reported. Uses git-clang-format (or clang-format-diff) from the Debian package clang-format.

BASE  a commit (id, branch, tag, HEAD~3...). Default: origin/main if it exists, else HEAD~1. When BASE is not an
      ancestor of HEAD (e.g. origin/main moved on), the merge base of BASE and HEAD is used.

Prints what clang-format would change on those lines (a diff) and the command that fixes them. Exit status:
  0  every changed line is formatted (or nothing changed)
  1  some changed line is not formatted
  2  bad argument, not in a git repository, no .clang-format, or clang-format not installed

With git-clang-format a renamed file counts as entirely changed (as for git clang-format itself).
EOF
}

die() {
  echo "check_format: $*" >&2
  exit 2
}

base_arg=
case $# in
  0) ;;
  1)
    case $1 in
      -h | --help) usage; exit 0 ;;
      -*) die "unknown option '$1' (see --help)" ;;
      '') die "BASE is empty (give a commit, or no argument for the default)" ;;
      *) base_arg=$1 ;;
    esac
    ;;
  *) die "at most one argument (BASE), got $#: $* (see --help)" ;;
esac

# The tools (Debian's clang-format package ships them unversioned, clang-format-14 with the -14 suffix).
clang_format=
for c in clang-format clang-format-14; do
  if command -v "$c" >/dev/null 2>&1; then clang_format=$(command -v "$c"); break; fi
done
[[ -n $clang_format ]] || die "clang-format is not installed: install the Debian package clang-format" \
  "(sudo apt-get install clang-format; scripts/setup.sh installs it)"
git_clang_format=
for c in git-clang-format git-clang-format-14; do
  if command -v "$c" >/dev/null 2>&1; then git_clang_format=$c; break; fi
done
clang_format_diff=
for c in clang-format-diff clang-format-diff-14; do
  if command -v "$c" >/dev/null 2>&1; then clang_format_diff=$c; break; fi
done
[[ -n $git_clang_format || -n $clang_format_diff ]] || die "neither git-clang-format nor clang-format-diff found" \
  "next to $clang_format: reinstall the Debian package clang-format"
command -v git >/dev/null 2>&1 || die "git is not installed"

# The repository of the current directory, else the one holding this script.
here=${BASH_SOURCE[0]%/*}
[[ $here == "${BASH_SOURCE[0]}" ]] && here=.
root=$(git rev-parse --show-toplevel 2>/dev/null) || root=$(git -C "$here" rev-parse --show-toplevel 2>/dev/null) ||
  die "not inside a git repository (run it from the work tree)"
cd "$root" || die "cannot enter $root"
[[ -f .clang-format ]] || die "no .clang-format at the repository root ($root)"

# BASE: the argument, else origin/main, else HEAD~1; always resolved to a commit id.
if [[ -n $base_arg ]]; then
  base=$(git rev-parse --verify --quiet "$base_arg^{commit}" 2>/dev/null) ||
    die "BASE '$base_arg' is not a commit of this repository"
  base_name=$base_arg
elif base=$(git rev-parse --verify --quiet "origin/main^{commit}"); then
  base_name=origin/main
elif base=$(git rev-parse --verify --quiet "HEAD~1^{commit}"); then
  base_name=HEAD~1
else
  die "no default BASE: neither origin/main nor HEAD~1 exists (give a commit)"
fi
if head=$(git rev-parse --verify --quiet "HEAD^{commit}") && ! git merge-base --is-ancestor "$base" "$head"; then
  fork=$(git merge-base "$base" "$head") || die "BASE '$base_name' shares no history with HEAD"
  echo "check_format: $base_name is not an ancestor of HEAD: checking the changes since the merge base ${fork:0:12}"
  base=$fork
fi
short=${base:0:12}

# Plain output whatever the user's git configuration says (no pager, no colour, a/ b/ prefixes).
export GIT_PAGER=cat GIT_CONFIG_COUNT=3
export GIT_CONFIG_KEY_0=color.ui GIT_CONFIG_VALUE_0=never
export GIT_CONFIG_KEY_1=diff.noprefix GIT_CONFIG_VALUE_1=false
export GIT_CONFIG_KEY_2=diff.mnemonicPrefix GIT_CONFIG_VALUE_2=false

if [[ -n $git_clang_format ]]; then
  # --diff: prints what it would change on the changed lines only; 0 nothing to do, 1 something to do, else error.
  out=$("$git_clang_format" --diff --quiet --binary "$clang_format" --style file --extensions h,cpp "$base" 2>&1)
  status=$?
  if ((status != 0 && status != 1)); then
    printf '%s\n' "$out" >&2
    die "$git_clang_format failed (status $status)"
  fi
  fix="git ${git_clang_format#git-} --binary $clang_format $short"
  [[ $clang_format == */clang-format ]] && fix="git ${git_clang_format#git-} $short"
  tool=$git_clang_format
else
  # clang-format-diff reads the changed lines from a zero-context diff of the work tree against BASE.
  diff=$(git diff --no-ext-diff --no-color -U0 "$base" -- '*.h' '*.cpp') || die "git diff against $short failed"
  out=$(printf '%s\n' "$diff" | "$clang_format_diff" -p1 -regex '.*\.(h|cpp)' -style file -binary "$clang_format" 2>&1)
  status=$?
  ((status == 0 || status == 1)) || { printf '%s\n' "$out" >&2; die "$clang_format_diff failed (status $status)"; }
  fix="git diff -U0 $short -- '*.h' '*.cpp' | $clang_format_diff -p1 -i -style file -binary $clang_format"
  tool=$clang_format_diff
fi

# Anything that is not a diff (e.g. "no modified files to format") means there is nothing to fix.
if [[ $out != *$'\n@@ '* && $out != '@@ '* ]]; then
  echo "check_format: the lines of *.h/*.cpp changed since $base_name ($short) are formatted ($tool)"
  exit 0
fi

printf '%s\n' "$out"
files=()
while IFS= read -r line; do
  case $line in
    '+++ b/'*) files+=("${line#+++ b/}") ;;
    '+++ '*) line=${line#+++ }; files+=("${line%%$'\t'*}") ;;  # clang-format-diff: "+++ path<TAB>(reformatted)"
  esac
done <<<"$out"
echo
echo "check_format: changed lines not formatted as .clang-format says, in ${#files[@]} file(s) (changes since" \
  "$base_name, $short):"
printf '  %s\n' "${files[@]}"
echo "Fix them (only the changed lines) from $root with:"
echo "  $fix"
[[ -n $git_clang_format ]] && echo "(git clang-format refuses files with unstaged changes: git add them first," \
  "or add -f)"
exit 1
