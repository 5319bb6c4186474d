"""Griffith's onset check on the energy release rate: J_c of ``critical_amplitude``.

Usage: ``python scripts/surfing_onset_check.py R/EPS HI STEPS [H/EPS]`` runs
:func:`surfing_griffith.critical_amplitude` with A²/G_eff from 0.88 to HI in STEPS steps,
adaptive (``adapt=band`` defaults, unstructured mesh of maxh = 10ε) without H/EPS, on a
fixed structured band of side H/EPS·ε, 0.35R long, with it, and prints the result
(``j_ratio`` = J_c / G_eff(h used), ``ratio`` = the break-point A_c² / G_eff) and, per step,
A², the crack advance / ε, J and the number of elements. The span must reach 10ε of
growth: HI = 1.6 at R/ε = 100, 1.2 (adaptive) or 1.35 (structured) at R/ε = 200.
"""

import importlib.util
import sys
from pathlib import Path

spec = importlib.util.spec_from_file_location(
    "surfing_griffith", Path(__file__).with_name("surfing_griffith.py")
)
sg = importlib.util.module_from_spec(spec)
spec.loader.exec_module(sg)


def main() -> None:
    ratio, hi, steps = float(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
    eps = sg.R / ratio
    h = float(sys.argv[4]) * eps if len(sys.argv) > 4 else None
    tag = f"{ratio:g}_{hi:g}_" + (sys.argv[4] if h else "adaptive")
    out = sg.critical_amplitude(
        eps,
        h,
        Path(f"results/onset_check/{tag}"),
        span=(0.88, hi),
        steps=steps,
        band_length=0.35,
    )
    skip = ("records", "release_rates")
    print({k: round(v, 4) if isinstance(v, float) else v for k, v in out.items() if k not in skip})
    print("h used / eps", round(out["h"] / eps, 4))
    for record, j in zip(out["records"], out["release_rates"], strict=True):
        advance = (record["tip1_x"] - sg.surfing.CRACK_LENGTH) / eps
        print(round(record["t"] ** 2, 4), round(advance, 2), round(j, 4), record["elements"])


if __name__ == "__main__":
    main()
