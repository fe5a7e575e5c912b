"""Prints the Panda's errors from the controller's telemetry until the TCP has settled."""
import sys

import hcc

with hcc.Client(sys.argv[1] if len(sys.argv) > 1 else "hcc_panda") as client:
    below = 0
    for t in client.telemetry(timeout=5.0):
        if t.header.seq % 250 == 0:
            print(f"cycle {t.header.seq:5d}: TCP error {1e3 * t.error_norm(0):8.3f} mm, "
                  f"orientation {t.error_norm(1):.4f} rad, posture {t.error_norm(2):.4f} rad")
        below = below + 1 if t.error_norm(0) < 1e-4 else 0
        if below == 100:  # 100 cycles within 0.1 mm
            print(f"cycle {t.header.seq:5d}: settled, TCP error {1e3 * t.error_norm(0):.4f} mm")
            break
