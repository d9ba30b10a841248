# Sourced by the shell tests: surgsim_reserve_domain SALT exports SURGSIM_DOMAIN, a DDS domain of 1..200 reserved for
# this shell across the machine, the same way tests/support/test_domain.h does for the C++ tests and
# web_support.py's private_domain for the Python ones: an exclusive flock on /tmp/surgsim-test-domains/<d>.lock, held
# on a descriptor the shell keeps open (and the programs it starts inherit) until it exits. The search starts at
# 1 + ($$ * 7 + SALT) % 200 and takes the next free domain. Call it in the test's own shell, not in $(...): a
# subshell's descriptor, and with it the lock, would close when the subshell ends. Fails (status 1) with the reason
# when all 200 are taken.
surgsim_reserve_domain() {
  local dir=/tmp/surgsim-test-domains salt=${1:-0} i d f fd
  mkdir -m 1777 "$dir" 2>/dev/null || [ -d "$dir" ] || { echo "surgsim_reserve_domain: cannot create $dir" >&2; return 1; }
  for ((i = 0; i < 200; i++)); do
    d=$((1 + ($$ * 7 + salt + i) % 200))
    f=$dir/$d.lock
    # Read-only, created only when missing: another user's lock file can still be opened.
    [ -e "$f" ] || : 2>/dev/null >>"$f"
    exec {fd}<"$f" || return 1
    if flock -n "$fd"; then
      export SURGSIM_DOMAIN=$d
      return 0
    fi
    exec {fd}<&-
  done
  echo "surgsim_reserve_domain: no free DDS test domain: all 200 (1..200) are held by other processes (locks in $dir/<domain>.lock)" >&2
  return 1
}
