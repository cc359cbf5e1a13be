#!/usr/bin/env bash
# Compiles the C# compact-frame decoder and its tests with Mono's `mcs` (C# 7,
# warnings as errors; the Unity adapter's plain-C# part included) and runs them
# with `mono` against the vectors in docs/compact-frames/, then compiles the
# Unity MonoBehaviour against a stub of UnityEngine. Exits non-zero on a
# failure. Needs `mcs` and `mono` (Debian: mono-mcs mono-runtime; scripts/csharp.sh
# installs them).
#
#   examples/clients/csharp/run-tests.sh
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
out=$(mktemp -d)
trap 'rm -rf "$out"' EXIT
mcs -langversion:7 -warnaserror -debug -out:"$out/CompactTests.exe" \
  "$here/Compact.cs" "$here/InbetweenStream.cs" "$here/CompactTests.cs"
mono --debug "$out/CompactTests.exe" "$here/../../../docs/compact-frames"
# The MonoBehaviour, type-checked against the UnityEngine members it uses (UnityEngineStub.cs).
mcs -langversion:7 -warnaserror -target:library -define:UNITY_5_3_OR_NEWER -out:"$out/InbetweenStream.dll" \
  "$here/Compact.cs" "$here/InbetweenStream.cs" "$here/UnityEngineStub.cs"
echo "ok   InbetweenStream.cs compiles as Unity would (UNITY_5_3_OR_NEWER, against UnityEngineStub.cs)"
