"""Validates Kubernetes manifests against the Kubernetes schemas (offline, strict:
an unknown field is an error), and lists their containers.

Usage: manifests.py FILE... — prints one JSON list: each container's manifest file,
workload, command, args and environment variable names. Exits non-zero naming the
first document that does not validate.
"""
import json
import sys

import kubernetes_validate
import kubernetes_validate.utils
import yaml

version = kubernetes_validate.utils.latest_version()
containers = []
for path in sys.argv[1:]:
    with open(path) as f:
        for doc in yaml.safe_load_all(f):
            if doc is None:
                continue
            try:
                kubernetes_validate.validate(doc, version, strict=True)
            except kubernetes_validate.ValidationError as e:
                sys.exit(f"{path}: {doc['kind']} {doc['metadata']['name']}: {e.message}")
            spec = doc.get("spec", {}).get("template", {}).get("spec", {})
            for c in spec.get("containers", []):
                containers.append(
                    {
                        "file": path,
                        "workload": doc["metadata"]["name"],
                        "command": c.get("command", []),
                        "args": c.get("args", []),
                        "env": [e["name"] for e in c.get("env", [])],
                    }
                )
print(json.dumps(containers))
