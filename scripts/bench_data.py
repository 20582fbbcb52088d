"""The GP benchmark data shared by the peer scripts (scripts/gp_sklearn_bench.py,
scripts/sgpr_peer.py) and vigp's examples/gp_train.rs and benches/gp.rs:
Weyl-sequence inputs in [-2, 2]^d, a smooth target plus 0.01 deterministic
noise. Also the load average the scripts print beside every timing."""
import numpy as np

# Fractional parts of sqrt(p) for the first primes: Weyl-sequence directions.
DIRS = [
    0.4142135623730951, 0.7320508075688772, 0.2360679774997897, 0.6457513110645906,
    0.31662479035539985, 0.6055512754639893, 0.12310562561766055, 0.3588989435406736,
]


def bench_data(n, d):
    """N x d inputs and N targets, identical to `bench_data` in examples/gp_train.rs."""
    i = np.arange(1, n + 1, dtype=float)
    X = np.stack([4.0 * ((i * DIRS[j]) % 1.0) - 2.0 for j in range(d)], axis=1)
    y = np.sin(3.0 * X[:, 0]) + np.cos(2.0 * X[:, 1])
    if d >= 4:
        y = y + 0.5 * X[:, 2] * X[:, 3]
    y = y + 0.01 * (((i * 0.7548776662466928) % 1.0) - 0.5)
    return X, y


def load():
    """The 1-, 5- and 15-minute load averages, or "?" off Linux."""
    try:
        return " ".join(open("/proc/loadavg").read().split()[:3])
    except OSError:
        return "?"
