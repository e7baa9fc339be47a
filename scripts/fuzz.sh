#!/usr/bin/env bash
# Runs every fuzz target (fuzz/fuzz_targets/*.rs) one after another on one core, from the committed
# seed corpus, for RUNS executions each (default 1000000), and prints executions and exec/s per target.
# One libFuzzer process at a time (no -jobs: with it libFuzzer forks workers that log to files).
# Needs cargo-fuzz (installed here if missing) and a nightly-capable compiler: on stable,
# RUSTC_BOOTSTRAP=1 enables the sanitizer-coverage flags it needs.
# Usage: [FUZZ_SECONDS=S] scripts/fuzz.sh [RUNS] [TARGET...]   (FUZZ_SECONDS caps each target's time)
set -euo pipefail
cd "$(dirname "$0")/../fuzz"
runs="${1:-1000000}"
shift || true
targets=("$@")
if [ ${#targets[@]} -eq 0 ]; then
    targets=(mgf obj gltf exr radiance points plot ies)
fi
command -v cargo-fuzz >/dev/null || cargo install cargo-fuzz --locked
export RUSTC_BOOTSTRAP=1
# No sanitizer: the readers are safe Rust, and ASan would halve the executions per second.
cargo fuzz build -s none
for target in "${targets[@]}"; do
    mkdir -p "corpus/$target" "artifacts/$target"
    log="artifacts/$target/run.log"
    start=$(date +%s)
    cargo fuzz run -s none "$target" "corpus/$target" -- \
        -runs="$runs" -max_total_time="${FUZZ_SECONDS:-0}" -max_len=65536 -rss_limit_mb=2048 -timeout=10 \
        -artifact_prefix="artifacts/$target/" 2>&1 | tee "$log" | grep -E "^#[0-9]+.*(INITED|DONE)|panicked|ERROR" || true
    seconds=$(( $(date +%s) - start ))
    done_line=$(grep -E "^Done [0-9]+ runs" "$log" || true)
    echo "$target: ${done_line:-no Done line (crash? see $log)} (${seconds} s wall)"
done
