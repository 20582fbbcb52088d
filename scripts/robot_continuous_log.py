#!/usr/bin/env python3
"""Continuous-time logs of the arm of tests/fixtures/robots/arm3.urdf for
vigp-runtime/tests/robot_identify.rs (`midpoint_bias_shrinks_...`).

Pinocchio (`pin` from PyPI) reads the same URDF; its articulated-body
algorithm gives q'' = ABA(q, v, tau - D v) (D the URDF's joint dampings,
which ABA does not apply itself), integrated by SciPy's DOP853 at
rtol = atol = 1e-12, interval by interval, with every joint driven by
inputs held constant over 10 ms (zero-order hold, so that logs sampled
every 10, 5 or 2.5 ms all see inputs held over their own intervals).
Positions are written every 2.5 ms.

    python3 scripts/robot_continuous_log.py > tests/fixtures/robots/arm3_continuous.json
"""
import json
import math
import os

import numpy as np
import pinocchio as pin
from scipy.integrate import solve_ivp

HERE = os.path.dirname(os.path.abspath(__file__))
URDF = os.path.join(HERE, "..", "tests", "fixtures", "robots", "arm3.urdf")
HOLD = 0.01  # s, the inputs' hold
SAMPLE = 0.0025  # s, the positions' sample period
SEGMENTS = 60  # 0.6 s per run


def main():
    model = pin.buildModelFromUrdf(URDF)
    data = model.createData()
    damping = np.array(model.damping)
    names = [model.names[i] for i in range(1, model.njoints)]
    runs = []
    for run, (q0, phase) in enumerate(
        [([0.2, -0.4, 0.05], 0.0), ([-0.5, 0.3, 0.1], 1.1)]
    ):
        q = np.array(q0, dtype=float)
        v = np.zeros(model.nv)
        inputs = []
        positions = [q.tolist()]
        for s in range(SEGMENTS):
            t = s * HOLD
            u = np.array(
                [
                    2.0 * math.sin((1.3 + 0.7 * j) * t * 10.0 + phase + j)
                    for j in range(model.nv)
                ]
            )
            inputs.append(u.tolist())

            def f(_t, y):
                qq, vv = y[: model.nq], y[model.nq :]
                a = pin.aba(model, data, qq, vv, u - damping * vv)
                return np.concatenate([vv, a])

            per = int(round(HOLD / SAMPLE))
            sol = solve_ivp(
                f,
                (t, t + HOLD),
                np.concatenate([q, v]),
                method="DOP853",
                rtol=1e-12,
                atol=1e-12,
                t_eval=[t + (k + 1) * SAMPLE for k in range(per)],
            )
            assert sol.success, sol.message
            for k in range(per):
                positions.append(sol.y[: model.nq, k].tolist())
            q, v = sol.y[: model.nq, -1], sol.y[model.nq :, -1]
        runs.append({"positions": positions, "inputs": inputs})
    out = {
        "what": "arm3.urdf under zero-order-hold inputs on every joint, DOP853 rtol=atol=1e-12 (pinocchio ABA)",
        "pinocchio": pin.__version__,
        "joints": names,
        "damping": damping.tolist(),
        "hold": HOLD,
        "sample": SAMPLE,
        "runs": runs,
    }
    print(json.dumps(out, separators=(",", ":")))


if __name__ == "__main__":
    main()
