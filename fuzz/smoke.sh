#!/usr/bin/env bash
# A short fuzz run of every target (CI's smoke test; `.ci/run` calls it). Needs a nightly
# toolchain (skipped with a message without one) and cargo-fuzz (installed when missing).
# Usage: fuzz/smoke.sh [SECONDS_PER_TARGET]   (default 5)
set -euo pipefail
cd "$(dirname "$0")"
seconds="${1:-5}"
targets=(radiance exr pfm sniff operator)

if ! rustup run nightly rustc --version >/dev/null 2>&1; then
    echo "fuzz smoke run skipped: no nightly toolchain (cargo-fuzz needs one)"
    exit 0
fi
if ! cargo +nightly fuzz --version >/dev/null 2>&1; then
    cargo install cargo-fuzz --version 0.13.2 --locked --quiet
fi

# The corpus: the kept seeds and regressions, and the library's test images for the
# decoders. fuzz/corpus/ is scratch space (not in git).
for t in "${targets[@]}"; do
    mkdir -p "corpus/$t"
    for dir in "seeds/$t" "regressions/$t"; do
        if [ -d "$dir" ]; then cp -f "$dir"/* "corpus/$t/"; fi
    done
done
for t in radiance exr sniff; do
    cp -f ../crates/visadapt/tests/data/*.hdr ../crates/visadapt/tests/data/*.exr "corpus/$t/"
done

log="$(mktemp)"
trap 'rm -f "$log"' EXIT
if ! cargo +nightly fuzz build --codegen-units 16 >"$log" 2>&1; then
    tail -30 "$log"
    exit 1
fi
for t in "${targets[@]}"; do
    if ! cargo +nightly fuzz run --codegen-units 16 "$t" "corpus/$t" -- \
        -max_total_time="$seconds" -rss_limit_mb=2048 -max_len=1048576 >"$log" 2>&1; then
        grep -v '^#' "$log" | tail -40
        echo "fuzz target $t failed; the input is in fuzz/artifacts/$t/ (keep it under fuzz/regressions/$t/ once fixed)"
        exit 1
    fi
    grep -E '^Done [0-9]+ runs' "$log" | sed "s/^/fuzz $t: /"
done
