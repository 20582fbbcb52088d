"""Reference LMLs for tests/gp/gp_robustness.rs
`the_optimiser_does_not_stop_on_a_spoiled_curvature_pair`.

Twelve points in [-2, 2]^2, each three times (N = 36), noise-free targets
y = sin(1.3 x1) + sin(2.6 x2 + 0.4)/2: a kernel matrix that is singular
but for the noise, which the optimum drives to its lower bound. scipy's
L-BFGS-B maximises scikit-learn's LML (inputs standardised with the
population std, normalize_y=True, vigp's default bounds) from the two
starts of the test, given in vigp's order ln l1, ln l2, ln sf2, ln sn2.

    pip install scikit-learn numpy scipy
    python scripts/gp_ill_conditioned_reference.py
"""
import warnings

import numpy as np
import scipy.optimize
from sklearn.gaussian_process import GaussianProcessRegressor
from sklearn.gaussian_process.kernels import RBF, ConstantKernel, WhiteKernel

warnings.filterwarnings("ignore")
U = np.array([
    [0.9601476930286554, -1.3000476558481955],
    [0.7590161390202672, 0.036874250999654024],
    [-0.40830572383584585, 1.126727977232659],
    [1.452728832776351, 1.5328112861284873],
    [-0.7928915086942023, -0.029483088045833217],
    [-0.9357615085543074, 0.30906703169021554],
    [1.2798138191028925, -1.2515352398237742],
    [1.853318130353871, -0.9717406257526813],
    [0.84943935781205, 0.942103043537267],
    [1.931406721384183, -1.1713350912793525],
    [-1.635960131150883, -0.9296893382434113],
    [1.1950925364743705, -0.5897993698876114],
])
X = np.vstack([U, U, U])
y = np.sin(1.3 * X[:, 0]) + np.sin(2.6 * X[:, 1] + 0.4) / 2
Xs = (X - X.mean(0)) / X.std(0)
kernel = ConstantKernel(1.0, (1e-4, 1e4)) * RBF([1.0, 1.0], (1e-3, 1e3)) + WhiteKernel(
    1e-2, (1e-10, 1e1)
)
gp = GaussianProcessRegressor(kernel, alpha=0.0, normalize_y=True, optimizer=None).fit(Xs, y)
STARTS = [
    [-2.5996445614259454, -1.0592842537359939, 6.036504859731457, -12.661476783774104],
    [-0.07962103399724096, 4.78792385993988, 6.520465856959136, -21.008555561000357],
]
for start in STARTS:
    t = np.array(start)
    th0 = np.r_[t[2], t[:2], t[3]]  # scikit-learn's order: sf2, l1, l2, sn2
    res = scipy.optimize.minimize(
        lambda th: tuple(-v for v in gp.log_marginal_likelihood(th, eval_gradient=True)),
        th0,
        method="L-BFGS-B",
        jac=True,
        bounds=gp.kernel.bounds,
    )
    print(f"start {start}: LML {-res.fun:.9f} after {res.nfev} evaluations ({res.message})")
