#!/usr/bin/env bash
# The C# compact-frame decoder (examples/clients/csharp) against the vectors
# in docs/compact-frames/: compiled with Mono's `mcs`, run with `mono`. Installs
# mono-mcs and mono-runtime with apt-get when `mcs` or `mono` is missing. No
# server needed. Exits non-zero when a test fails.
#
#   scripts/csharp.sh          # install Mono if needed, run the tests
#   scripts/csharp.sh --help   # this text
set -euo pipefail
source "$(dirname "$0")/lib.sh"
ib_help "$@"
cd "$IB_ROOT"

if ! command -v mcs >/dev/null 2>&1 || ! command -v mono >/dev/null 2>&1; then
  DEBIAN_FRONTEND=noninteractive apt-get update -q
  DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends mono-mcs mono-runtime
fi
bash examples/clients/csharp/run-tests.sh
