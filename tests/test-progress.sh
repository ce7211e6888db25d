#!/usr/bin/env bash
# The progress line of walk and bench on stderr (tools/progress.h): piped,
# plain lines (every TW_PROGRESS_INTERVAL_S seconds; 0: every frame) with
# done/total, percent, ETA and rate, never a carriage return, nothing on
# stdout; none with --quiet; none for a run shorter than the default 10 s; a
# bad interval is one warning. On a terminal (util-linux script, where there
# is one) one line rewritten in place with \r and cleared at the end.
set -u
tw=${1:?usage: test-progress.sh PATH/TO/tileworld}
. "$(dirname "$0")/test-lib.sh"

# Full detail: the progress line does not depend on the levels, which a
# process showing the city builds first (about 3 s; ten under AddressSanitizer).
small=(--size 64x36 --png-every 0 --frames 12 --max-screen-error 0)

# progress_lines FILE DIR: the plain progress lines of the run into DIR.
progress_lines() { grep -c "^$2: [0-9]*/[0-9]* frames ([0-9.]* %)" "$1"; }

# Piped, a line at every frame, and the last saying the time taken.
TW_PROGRESS_INTERVAL_S=0 "$tw" walk "${small[@]}" --out "$tmp/w" >"$tmp/out" 2>"$tmp/err"
rc=$?
[ "$rc" -eq 0 ] && ok || bad "walk exited $rc: $(cat "$tmp/err")"
n=$(progress_lines "$tmp/err" "$tmp/w")
[ "$n" -eq 13 ] && ok || bad "walk, TW_PROGRESS_INTERVAL_S=0: $n progress lines (expected 12 and the last): $(cat "$tmp/err")"
grep -q "^$tmp/w: 6/12 frames (50.0 %), ETA [0-9]*:[0-5][0-9]:[0-5][0-9], [0-9.e+]* frames/s, elapsed [0-9]*:[0-9][0-9]:[0-9][0-9]; [0-9.]* ms/frame$" "$tmp/err" &&
    ok || bad "walk: no progress line of the expected form: $(cat "$tmp/err")"
grep -q "^$tmp/w: 12/12 frames (100.0 %), done in [0-9]*:[0-9][0-9]:[0-9][0-9]" "$tmp/err" && ok ||
    bad "walk: no last line: $(tail -2 "$tmp/err")"
if grep -q $'\r' "$tmp/err"; then bad "walk piped: a carriage return on stderr"; else ok; fi
if grep -q 'frames (' "$tmp/out"; then bad "walk: progress on stdout: $(cat "$tmp/out")"; else ok; fi

# --quiet: no progress, whatever the interval.
TW_PROGRESS_INTERVAL_S=0 "$tw" walk "${small[@]}" --quiet --out "$tmp/q" >"$tmp/out" 2>"$tmp/err"
[ "$(progress_lines "$tmp/err" "$tmp/q")" -eq 0 ] && ok || bad "walk --quiet printed progress: $(cat "$tmp/err")"

# The default interval (10 s): a run of a second or two prints none.
env -u TW_PROGRESS_INTERVAL_S "$tw" walk "${small[@]}" --out "$tmp/d" >"$tmp/out" 2>"$tmp/err"
[ "$(progress_lines "$tmp/err" "$tmp/d")" -eq 0 ] && ok || bad "a short walk printed progress: $(cat "$tmp/err")"

# A bad interval: one warning line, the default kept, the run goes on.
TW_PROGRESS_INTERVAL_S=soon "$tw" walk "${small[@]}" --out "$tmp/b" >"$tmp/out" 2>"$tmp/err"
rc=$?
[ "$rc" -eq 0 ] && [ "$(grep -c 'TW_PROGRESS_INTERVAL_S' "$tmp/err")" -eq 1 ] &&
    [ "$(progress_lines "$tmp/err" "$tmp/b")" -eq 0 ] && ok ||
    bad "TW_PROGRESS_INTERVAL_S=soon: exit $rc, $(cat "$tmp/err")"

# bench: the same line, over its frames (each frame runs every method).
TW_PROGRESS_INTERVAL_S=0 "$tw" bench --methods vfc,chc --size 64x36 --png-every 0 --frames 6 \
    --out "$tmp/bn" >"$tmp/out" 2>"$tmp/err"
rc=$?
n=$(progress_lines "$tmp/err" "$tmp/bn")
[ "$rc" -eq 0 ] && [ "$n" -eq 7 ] && ok || bad "bench: exit $rc, $n progress lines: $(cat "$tmp/err")"
if grep -q $'\r' "$tmp/err"; then bad "bench piped: a carriage return on stderr"; else ok; fi

# A terminal: stderr on a pseudo-terminal (stdout to a file), one line
# redrawn with \r and cleared (\r, spaces, \r) before the program's last line.
if command -v script >/dev/null && script -qec true /dev/null >/dev/null 2>&1; then
    script -qec "'$tw' walk --size 64x36 --png-every 0 --frames 40 --out '$tmp/t' >'$tmp/t.out'" \
        /dev/null >"$tmp/tty" 2>&1
    rc=$?
    [ "$rc" -eq 0 ] && ok || bad "walk on a terminal exited $rc: $(cat -A "$tmp/tty" | head -c 600)"
    grep -q $'\r'"$tmp/t: 1/40 frames (2.5 %)" "$tmp/tty" && ok ||
        bad "terminal: no line drawn in place: $(cat -A "$tmp/tty" | head -c 600)"
    grep -q $'\r   *\r'"tileworld: wrote" "$tmp/tty" && ok ||
        bad "terminal: the line was not cleared: $(cat -A "$tmp/tty" | head -c 600)"
    if grep -q 'done in' "$tmp/tty"; then bad "terminal: a plain last line"; else ok; fi
    if grep -q 'frames (' "$tmp/t.out"; then bad "terminal: progress on stdout"; else ok; fi
else
    echo "script (util-linux) cannot run here: the terminal checks are skipped"
fi

finish test-progress
