#!/usr/bin/env bash
# Builds the downstream crate with Cargo's default release profile and checks its binary:
# no call of the C library's software `fmaf` may be linked in. Each kernel with fused
# multiply-adds is compiled inside a function with AVX2/FMA enabled (src/simd.rs); if one
# fell out of it (a closure compiled on its own, for the baseline), every multiply-add
# there would become an `fmaf` call, 10-20 times slower, with the same results. This
# happened with 16 code-generation units and no LTO before the closures were marked
# `#[inline(always)]`.
set -euo pipefail
cd "$(dirname "$0")"
target="${CARGO_TARGET_DIR:-../../target}/downstream"
cargo build --release --locked --quiet --target-dir "$target"
bin="$target/release/visadapt-downstream-check"
"$bin"
if nm "$bin" | grep -qE ' (fmaf|fmaf_with_fma|fmaf_fallback)$'; then
    echo "downstream check: $bin links the software fmaf: a vector kernel is compiled outside its target-feature function" >&2
    nm -C "$bin" | grep -E 'fmaf' >&2
    exit 1
fi
echo "downstream check: no software fmaf in a default-profile build"
