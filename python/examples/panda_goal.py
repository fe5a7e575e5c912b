"""Moves the Panda's TCP to a new goal at run time and waits until it is there.

Usage: python panda_goal.py [NAMESPACE [X Y Z]] (default hcc_panda, 0.55 0.10 0.30).
"""

import sys

import hcc

namespace = sys.argv[1] if len(sys.argv) > 1 else "hcc_panda"
goal = [float(v) for v in sys.argv[2:5]] if len(sys.argv) >= 5 else [0.55, 0.10, 0.30]

with hcc.Client(namespace) as client:
    seq = client.set_goal(0, goal, duration=1.0)  # level 0: the TCP position, m
    try:
        answer = client.wait_until_accepted(seq, timeout=2.0)
    except hcc.SetpointRejected as e:
        sys.exit(f"goal {goal} rejected: {e.rejection.label if e.rejection else e.code}")
    print(f"goal {goal} accepted, transition {answer.duration_s:.2f} s")
    error = client.wait_until_converged(0, tolerance=1e-3, timeout=10.0)
    print(f"TCP within {1e3 * error:.3f} mm of the goal")
