#!/usr/bin/env bash
# Validates the Kubernetes manifests of deploy/k8s/ against Kubernetes' own API schemas, offline, with
# PyPI's kubernetes-validate (installed into a virtual environment under target/, once). No cluster
# runs here, so this is what is checked: every object's fields, types and required keys, strictly
# (an unknown field is an error). Run by .ci/run.
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/../.."
KUBERNETES_VERSION=${KUBERNETES_VERSION:-1.31.0}
venv=target/k8s-validate
if [[ ! -x $venv/bin/kubernetes-validate ]]; then
    python3 -m venv "$venv"
    "$venv/bin/python" -m pip install --quiet --disable-pip-version-check "kubernetes-validate==1.37.0"
fi
"$venv/bin/kubernetes-validate" --strict --kubernetes-version "$KUBERNETES_VERSION" deploy/k8s/*.yaml
