"""Several recorders' files re-fused through the Python package with align="gnss", as
`railfuse refuse FILES --align gnss` does. Usage: python_align.py CONFIG OUT FILE...; prints
the accuracy as JSON (the Rust test compares the output with the CLI's byte for byte)."""
import json
import sys

import railfuse

config, out, files = sys.argv[1], sys.argv[2], sys.argv[3:]
report = railfuse.refuse(files, config, out, align="gnss")
print(json.dumps({"rmse": report["eval"]["pipelines"][0]["position_error_m"]["rmse"]}))
