# What the shell tests of the tileworld command share (sourced, not run):
# a temporary folder $tmp removed on exit, counted checks ok and bad, and
# finish NAME, the last line and the exit status.
# Under the sanitizer CI run, LeakSanitizer would add its list of the
# suppressions used (OSMesa's) to stderr, whose lines the tests count.
export LSAN_OPTIONS="${LSAN_OPTIONS:+$LSAN_OPTIONS:}print_suppressions=0"
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
passed=0
failed=0

ok() { passed=$((passed + 1)); }
bad() { failed=$((failed + 1)); echo "FAIL: $*" >&2; }

# finish NAME: prints "NAME: P passed, F failed" and exits 0 only with no failure.
finish() {
    echo "${1:+$1: }$passed passed, $failed failed"
    [ "$failed" -eq 0 ]
    exit
}
