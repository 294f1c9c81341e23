"""pykalman's EM on the data `railfuse bench --em` wrote: estimates Q and R from the same start
with the same number of iterations, and times `KalmanFilter.em` alone.

Usage: python pykalman_em.py DATA.json  ->  JSON {"q": [[..]], "r": [[..]], "seconds": s}
"""
import json
import sys
import time

import numpy as np
from pykalman import KalmanFilter

data = json.load(open(sys.argv[1]))
kf = KalmanFilter(
    transition_matrices=np.array(data["transition"]),
    observation_matrices=np.array(data["observation"]),
    transition_covariance=np.array(data["process_noise"]),
    observation_covariance=np.array(data["measurement_noise"]),
    initial_state_mean=np.array(data["initial_mean"]),
    initial_state_covariance=np.array(data["initial_covariance"]),
    em_vars=["transition_covariance", "observation_covariance"],
)
z = np.array(data["measurements"])
started = time.perf_counter()
kf = kf.em(z, n_iter=data["iterations"])
seconds = time.perf_counter() - started
json.dump(
    {
        "q": kf.transition_covariance.tolist(),
        "r": kf.observation_covariance.tolist(),
        "seconds": seconds,
    },
    sys.stdout,
)
