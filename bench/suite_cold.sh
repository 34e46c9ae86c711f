#!/bin/bash
# A cold run of the README's test command: a fresh clone of REV (no kernel cache, no bytecode),
# with an editable install in VENV (made once: python3 -m venv VENV && VENV/bin/pip install -e 'CLONE[test]'),
# the compile log and the test timeline of bench/suitelog, /usr/bin/time -v and uptime before and after.
#   bench/suite_cold.sh REPO REV OUT [CLONE [VENV]]      then: python bench/suite_report.py OUT
set -u
REPO=$1; REV=$2; O=$3; CLONE=${4:-/tmp/suite-cold/p}; VENV=${5:-/tmp/suite-cold/venv}
HERE=$(cd "$(dirname "$0")" && pwd)
mkdir -p "$O" "$(dirname "$CLONE")"
rm -rf "$CLONE" && git clone -q "$REPO" "$CLONE" && git -C "$CLONE" checkout -q "$REV" || exit 1
rm -rf "${XDG_CACHE_HOME:-$HOME/.cache}/warpcli"; unset NUMBA_CACHE_DIR  # numba and warpcli cache beside the code
[ -d "$VENV" ] || { python3 -m venv "$VENV" && "$VENV/bin/pip" install -q -e "$CLONE[test]"; }
cp -r "$HERE/suitelog" "$O/plug"
cd "$CLONE" && . "$VENV/bin/activate"
uptime > "$O/uptime_before"; date +%s.%N > "$O/t0"
SUITELOG_COMPILES=$O/compile.jsonl SUITELOG_TESTS=$O/timeline.jsonl SUITELOG_EVENTS=$O/start.jsonl PYTHONPATH=$O/plug \
  /usr/bin/time -v -o "$O/time.txt" python -m pytest -q -n auto -p suiteplug --durations=40 > "$O/out.txt" 2>&1
echo $? > "$O/rc"; date +%s.%N > "$O/t1"; uptime > "$O/uptime_after"
