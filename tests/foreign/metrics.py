"""Scrapes a metrics endpoint and parses it with the Prometheus project's own Python
parser (OpenMetrics text), as a monitoring system would.

Usage: metrics.py URL — prints one JSON object: each metric family's type and its
samples as [name, labels, value].
"""
import json
import sys
import urllib.request

from prometheus_client.openmetrics.parser import text_string_to_metric_families

with urllib.request.urlopen(sys.argv[1], timeout=10) as response:
    text = response.read().decode("utf-8")
families = {
    family.name: {
        "type": family.type,
        "samples": [[s.name, s.labels, s.value] for s in family.samples],
    }
    for family in text_string_to_metric_families(text)
}
print(json.dumps(families))
