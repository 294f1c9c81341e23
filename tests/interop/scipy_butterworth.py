"""railfuse's Butterworth stages against scipy.signal. Usage: scipy_butterworth.py CASES.json,
where each case holds the design (kind, edges in Hz, sample rate), railfuse's second-order
sections, an input signal and railfuse's output of it. Prints, as JSON, the largest
difference of the sections and of the outputs over all cases."""
import json
import sys

import numpy as np
from scipy.signal import butter, sosfilt

cases = json.load(open(sys.argv[1]))
worst = {"sos": 0.0, "output": 0.0, "cases": len(cases)}
for c in cases:
    edges = c["edges_hz"][0] if c["kind"] == "lowpass" else c["edges_hz"]
    sos = butter(4, edges, btype=c["kind"], output="sos", fs=c["fs_hz"])
    ours = np.array(c["sos"])
    worst["sos"] = max(worst["sos"], float(np.max(np.abs(sos - ours))))
    y = sosfilt(sos, np.array(c["input"]))
    worst["output"] = max(worst["output"], float(np.max(np.abs(y - np.array(c["output"])))))
print(json.dumps(worst))
