"""Griffith's theory on the surfing scene: critical amplitude and steady propagation.

Question: does the discrete AT model of ngat crack like Griffith's theory says, with the
effective toughness G_eff(h) = 1 + h/(4ε) + (h/ε)²/32 of a crack band one element wide
(docs/design.md, scene 2)? The scene is ``geometries/surfing.py``: a strip with a pre-crack whose
frame Ω_D carries the mode-III tip field U = A sqrt(2r/π) sin(θ/2), energy release rate G = A².

(a) Critical amplitude: the tip field stays at the pre-crack's tip (V = 0) and A is ramped;
    the crack starts to grow at A_c² (:func:`ngat.geometries.surfing.onset`), which should equal
    G_eff(h) within 3 %.
(b) Steady propagation: A² = 1.2 G_eff(h) and the tip field moves at V; after a transient the
    crack tip moves at V and the surface energy grows at G_eff per unit crack advance
    (:func:`ngat.geometries.surfing.steady_rates`), within 2 %.

h is the side of the squares of the structured band along the crack path (the spacing of the
node lines parallel to the crack); the mesh is fixed (``adapt=fixed``). Both measures carry a
bias of order ε/R (AT2 damages the whole body a little; R = 0.6 is the distance from the tip
to the frame), so the study varies R/ε through ε with the geometry fixed, and h/ε.

Run ``python scripts/surfing_griffith.py`` (the study, ``--out`` default
``results/surfing_griffith``: ``griffith.csv``) or ``--quick`` (the coarse variant the tests
use: h = ε, R/ε = 200 for (a) and 400 for (b)).
"""

from __future__ import annotations

import argparse
import csv
import time
from pathlib import Path

import numpy as np

from ngat.cli import parse_settings
from ngat.driver import run
from ngat.elasticity import elasticity
from ngat.geometries import surfing, surfing_mode_i
from ngat.parameters import Parameters

R = surfing.HEIGHT / 2 - surfing.FRAME
"""Distance from the pre-crack's tip to the frame."""


MAXH_OVER_EPS = 10.0
"""Initial mesh size of the adaptive variant, in units of ε: no element resolves ε before the
crack band is refined (:mod:`ngat.band`)."""


def nominal_band(eps: float) -> float:
    """Return the node-line spacing the default crack band aims at: legs of band_h·ε/√2."""
    return Parameters().adaptivity.band_h * eps / np.sqrt(2)


def band_size(records: list[dict]) -> float:
    """Return the median ``h_crack`` of the records: the crack band size an adaptive run used."""
    return float(np.median([r["h_crack"] for r in records if r["h_crack"] > 0]))


def adaptive_overrides(eps: float, h: float | None, overrides: dict) -> dict:
    """Return the run's parameters: with ``h=None`` the adaptive defaults from maxh = 10ε.

    A fixed band of h ≥ ε is studied on purpose (its toughness G_eff(h)), so the check that
    refuses meshes that cannot resolve ε is off for it.
    """
    if h is not None:
        return {"resolve_eps": False, **overrides}
    return {"maxh": MAXH_OVER_EPS * eps, **overrides}


def adaptive_scene(mode: str, **kwargs):
    """Return the unstructured surfing scene of ``mode``: "iii" (anti-plane) or "i" (plane strain).

    The mode-I scene (``geometries/surfing_mode_i.py``) has Williams' K_I field with G = A² and
    is meshed by Netgen only; ``kwargs`` are those of :func:`ngat.geometries.surfing.make_scene`.
    """
    if mode == "iii":
        return surfing.make_scene(**kwargs, structured=False)
    for key in ("h_band", "band_end", "half_width"):
        kwargs.pop(key)
    return surfing_mode_i.make_scene(**{**kwargs, "name": kwargs["name"] + "-mode-i"})


def release_rates(
    folder: Path, eps: float, eta: float, mode: str = "iii", precrack: bool | float = False
) -> list[float]:
    """Return J (:func:`ngat.geometries.surfing.energy_release_rate`) at each written step.

    Reads ``fields/step_*.vtu`` of a results folder (written at every step by default); ``mode``
    "i" takes u as the plane-strain displacement of ``surfing-mode-i``. With ``precrack=True``
    the pre-crack's band along the whole slit crosses the annulus and J + Γ is returned
    (:func:`~ngat.geometries.surfing.band_surface_energy`); a pre-crack of length ℓ ending at
    the slit's tip lies inside the annulus if ℓ is below its inner radius (0.27), and J alone
    is returned.
    """
    import pyvista

    density = (
        elasticity("plane_strain", surfing_mode_i.YOUNG, surfing_mode_i.POISSON)
        if mode == "i"
        else None
    )
    rates = []
    for path in sorted((Path(folder) / "fields").glob("step_*.vtu")):
        grid = pyvista.read(path)
        cells = np.asarray(grid.cells).reshape(-1, 4)[:, 1:]
        u, v = grid.point_data["u"], grid.point_data["v"]
        j = surfing.energy_release_rate(grid.points, cells, u, v, eps, eta, elasticity=density)
        if precrack is True:
            j += surfing.band_surface_energy(grid.points, cells, v, eps)
        rates.append(j)
    return rates


def critical_amplitude(
    eps: float,
    h: float,
    folder: Path,
    span=(0.88, 1.12),
    steps: int = 25,
    mode: str = "iii",
    band_length: float = 0.15,
    precrack: bool | float = False,
    **overrides,
) -> dict:
    """Ramp A with the tip field fixed at the pre-crack's tip; return A_c² against G_eff(h).

    Parameters
    ----------
    eps, h
        ε and the band's cell side; ``h=None``: the adaptive defaults (``adapt=band``) from an
        unstructured mesh with maxh = 10ε, and h the size of the crack's elements the run used
        (:func:`band_size`).
    folder
        Results folder of the run.
    span
        Range of A² / G_eff(h) covered, in ``steps`` load steps equally spaced in A².
    mode
        "iii" (anti-plane) or "i" (plane strain; adaptive runs only, :func:`adaptive_scene`).
    band_length
        Length of a structured band beyond a₀, in units of R (room for 10ε of growth and
        more at R/ε ≥ 100 needs 0.35; the default keeps the A_c² checks' meshes).
    precrack
        Mode I: v = 0 on the slit's faces from the start (a phase-field pre-crack,
        :func:`ngat.geometries.surfing_mode_i.on_slit`); a length ℓ: on the last ℓ of the slit.
    overrides
        Further parameters of the run (``am_tol``, ...).

    Returns
    -------
    dict
        ``a_c_sq``, ``g_eff``, ``ratio`` = A_c² / G_eff, ``wall_s`` and the run's records;
        ``release_rates`` (J per step), ``j_c`` (:func:`~ngat.geometries.surfing.
        griffith_toughness`: J over the steps whose crack has grown 10ε or more) and
        ``j_ratio`` = J_c / G_eff, Griffith's check on the energy release rate the crack
        grows at. A² overstates that rate (AT2 softens the whole body, J/A² ≈ 0.90 at
        R/ε = 100 before the crack moves), so A_c² is late by a bias of order ε/R; and the
        break point of a smooth creep curve depends on the span. J_c needs a span that
        reaches growth: up to 1.6 G_eff at R/ε = 100, 1.2 at R/ε = 200 (else NaN).

    Notes
    -----
    A structured band ends at a₀ + ``band_length`` R; steps beyond 5ε before its end are left
    out of J_c: the coarse elements there hold the crack back.
    """
    amplitude = np.sqrt(
        surfing.effective_toughness(h or nominal_band(eps), eps) * np.linspace(*span, steps)
    )
    top = float(amplitude[-1])
    # A(t) = t: amplitude A_max reached at t = ramp = A_max.
    kwargs = dict(
        amplitude=top, speed=0.0, ramp=top, eps=eps, h_band=h, times=np.round(amplitude, 12),
        band_end=surfing.CRACK_LENGTH + band_length * R, half_width=6 * eps,
        name="surfing-critical",
    )  # fmt: skip
    if precrack:
        kwargs["precrack"] = precrack
    scene = surfing.make_scene(**kwargs) if h else adaptive_scene(mode, **kwargs)
    parameters, times = scene.configure(overrides=adaptive_overrides(eps, h, overrides))
    begin = time.perf_counter()
    result = run(scene, parameters, times, folder)
    records = result.records
    a_c_sq = surfing.onset([r["t"] ** 2 for r in records], [r["tip1_x"] for r in records])
    grown = [r for r in records if r["t"] ** 2 > a_c_sq]
    structured = h is not None
    h = h or band_size(grown)
    g_eff = surfing.effective_toughness(h, eps)
    rates = release_rates(folder, eps, parameters.model.eta, mode, precrack)
    end = surfing.CRACK_LENGTH + band_length * R - 5 * eps if structured else None
    j_c = surfing.griffith_toughness(rates, [r["tip1_x"] for r in records], eps, end=end)
    return {
        "release_rates": rates,
        "j_c": j_c,
        "j_ratio": j_c / g_eff,
        "a_c_sq": a_c_sq,
        "g_eff": g_eff,
        "h": h,
        "ratio": a_c_sq / g_eff,
        "wall_s": time.perf_counter() - begin,
        "records": records,
        "elements": records[-1]["elements"],
        "h_crack": records[-1]["h_crack"],
    }


def steady_propagation(
    eps: float,
    h: float,
    folder: Path,
    speed: float = 0.4,
    advance_per_step: float = 2.0,
    steps: int = 17,
    skip: int = 9,
    lag: float = 0.0,
    ramp: float = 0.05,
    mode: str = "iii",
    precrack: bool | float = False,
    **overrides,
) -> dict:
    """Drive the crack with A² = 1.2 G_eff(h) at speed V; return its speed and toughness.

    Parameters
    ----------
    eps, h
        ε and the band's cell side; ``h=None``: the adaptive defaults (``adapt=band``) from an
        unstructured mesh with maxh = 10ε, and h the size of the crack's elements the run used
        (:func:`band_size`).
    folder
        Results folder of the run.
    speed
        V.
    advance_per_step
        V Δt in units of h (of ε for the adaptive run).
    steps
        Number of load steps.
    skip
        Steps left out of the fit (the ramp and the transient).
    lag
        The imposed tip starts this far behind a₀. Starting it closer to the steady lead
        (about 0.1) shortens the first jump of the crack but moves the imposed tip towards
        the frame, where the steady lead changes with position (finite strip).
    ramp
        Time over which the amplitude is ramped in; a slow ramp lets the crack settle at the
        steady lead instead of overshooting it.
    mode
        "iii" (anti-plane) or "i" (plane strain; adaptive runs only, :func:`adaptive_scene`).
    precrack
        Mode I: a phase-field pre-crack on the slit (:func:`critical_amplitude`).
    overrides
        Further parameters of the run.

    Returns
    -------
    dict
        ``speed_ratio`` = tip speed / V, ``toughness_ratio`` = (dS/da) / G_eff,
        ``stick_slip`` (the scatter of the advance per step, :func:`~ngat.geometries.surfing.
        steady_rates`),
        ``tip_g_drift`` = relative change over the window of Griffith's G of a sharp crack
        ending at the measured tip (:func:`~ngat.geometries.surfing.sharp_crack_release_rate`),
        ``g_eff``,
        ``lead`` (crack tip − imposed tip at the end), ``wall_s`` and the run's records.
    """
    dt = advance_per_step * (h or eps) / speed
    times = np.round(dt * np.arange(1, steps + 1), 12)
    start = surfing.CRACK_LENGTH - lag
    kwargs = dict(
        amplitude=np.sqrt(
            surfing.OVERLOAD * surfing.effective_toughness(h or nominal_band(eps), eps)
        ),
        speed=speed, ramp=ramp, eps=eps, h_band=h, times=times, tip_start=start,
        band_end=start + speed * times[-1] + 0.25 * R, half_width=6 * eps,
        name="surfing-steady",
    )  # fmt: skip
    if precrack:
        kwargs["precrack"] = precrack
    scene = surfing.make_scene(**kwargs) if h else adaptive_scene(mode, **kwargs)
    parameters, times = scene.configure(overrides=adaptive_overrides(eps, h, overrides))
    begin = time.perf_counter()
    records = run(scene, parameters, times, folder).records
    window = records[skip:]
    rates = surfing.steady_rates(
        [r["t"] for r in window], [r["tip1_x"] for r in window], [r["surface"] for r in window]
    )
    last = records[-1]
    h = h or band_size(window)
    g_eff = surfing.effective_toughness(h, eps)
    # Griffith's G of a sharp crack ending at the measured tip, at the window's ends: a crack
    # of constant toughness keeps it constant.
    tip_g = (
        [
            surfing.sharp_crack_release_rate(r["tip1_x"], start + speed * r["t"])
            for r in (window[0], window[-1])
        ]
        if mode == "iii"
        else [np.nan, np.nan]
    )
    return {
        "speed_ratio": rates["speed"] / speed,
        "toughness_ratio": rates["toughness"] / g_eff,
        "stick_slip": rates["stick_slip"],
        "tip_g_drift": tip_g[1] / tip_g[0] - 1,
        "g_eff": g_eff,
        "h": h,
        "elements": last["elements"],
        "h_crack": last["h_crack"],
        "lead": last["tip1_x"] - (start + speed * last["t"]),
        "wall_s": time.perf_counter() - begin,
        "records": records,
    }


QUICK = {"critical": (R / 400, 1.0), "steady": (R / 400, 1.0)}
"""(ε, h/ε) of the coarse variant: R/ε = 200 for (a), 400 for (b)."""

STUDY = [(60, 1.0), (200, 1.0), (400, 1.0), (200, 0.5), (400, 0.5)]
"""(R/ε, h/ε) of the study."""


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the coarse test variant only")
    parser.add_argument("--out", type=Path, default=Path("results/surfing_griffith"))
    parser.add_argument("--steps", type=int, default=17, help="load steps of (b)")
    parser.add_argument("--skip", type=int, default=9, help="steps of (b) left out of the fit")
    parser.add_argument("--cases", nargs="+", default=None, help="R/eps:h/eps pairs, e.g. 400:1")
    parser.add_argument(
        "--mode", choices=["iii", "i"], default="iii",
        help="anti-plane (iii) or plane-strain (i) surfing; mode i with --adaptive only",
    )  # fmt: skip
    parser.add_argument(
        "--precrack", action="store_true",
        help="mode i: v = 0 on the slit's faces from the start (a phase-field pre-crack)",
    )  # fmt: skip
    parser.add_argument(
        "--precrack-length", type=float, default=None, metavar="L",
        help="with --precrack: the pre-crack on the last L eps of the slit only (default the "
        "whole slit; at R/eps = 1000 the band along the whole slit is too many elements)",
    )  # fmt: skip
    parser.add_argument(
        "--adaptive", type=float, nargs="+", default=None, metavar="R/EPS",
        help="adaptive runs (adapt=band defaults, unstructured mesh of maxh = 10 eps) instead",
    )  # fmt: skip
    parser.add_argument(
        "--eta", type=float, default=None,
        help="residual stiffness eta (default the package's, 1e-5): a crack band stores "
        "energy ~ eta [u]^2 / h per unit length (docs/adaptivity.md)",
    )  # fmt: skip
    parser.add_argument(
        "--am-stop", choices=["contraction", "change"], default=None,
        help="stopping test of the alternating minimisation (default the package's, "
        "contraction; change: the paper's, which stops a creeping crack early)",
    )  # fmt: skip
    parser.add_argument(
        "--onset-only", action="store_true",
        help="run the critical-amplitude ramp (a) only, not the steady propagation (b)",
    )  # fmt: skip
    parser.add_argument(
        "--span", type=float, nargs=2, default=(0.88, 1.12), metavar=("LOW", "HIGH"),
        help="range of A^2 / G_eff of the ramp (a)",
    )  # fmt: skip
    parser.add_argument("--onset-steps", type=int, default=25, help="load steps of (a)")
    parser.add_argument(
        "--set", action="append", default=[], metavar="NAME=VALUE",
        help="change a parameter of the runs, e.g. --set remesh_radius=10 --set band_h=0.18",
    )  # fmt: skip
    args = parser.parse_args()
    settings = parse_settings(args.set)
    cases = [(R / QUICK["steady"][0], 1.0)] if args.quick else STUDY
    if args.cases:
        cases = [tuple(float(v) for v in case.split(":")) for case in args.cases]
    if args.adaptive:
        cases = [(ratio, None) for ratio in args.adaptive]
    rows = []
    for ratio, h_over_eps in cases:
        eps = R / ratio
        h = h_over_eps * eps if h_over_eps else None
        tag = f"R{ratio:g}_h{h_over_eps:g}" if h else f"R{ratio:g}_adaptive"
        tag += "" if args.mode == "iii" else "_mode_i"
        precrack = args.precrack
        if args.precrack and args.precrack_length:
            tag += f"_precrack{args.precrack_length:g}"
            precrack = args.precrack_length * eps
        elif args.precrack:
            tag += "_precrack"
        options = {"mode": args.mode, "precrack": precrack}
        if args.eta is not None:
            options["eta"] = args.eta
            tag += f"_eta{args.eta:g}"
        if args.am_stop is not None:
            options["am_stop"] = args.am_stop
            tag += f"_{args.am_stop}"
        options.update(settings)
        tag += "".join(f"_{name}{value}" for name, value in settings.items())
        a = critical_amplitude(
            eps, h, args.out / f"critical_{tag}", span=tuple(args.span), steps=args.onset_steps,
            **options,
        )  # fmt: skip
        row = {
            "R_over_eps": ratio, "mesh": "structured" if h else "adaptive",
            "h_over_eps (a)": round(a["h"] / eps, 4), "elements (a)": a["elements"],
            "g_eff": round(a["g_eff"], 5), "a_c_sq_over_g_eff": round(a["ratio"], 4),
            "j_c_over_g_eff": round(a["j_ratio"], 4), "critical_wall_s": round(a["wall_s"], 1),
        }  # fmt: skip
        if not args.onset_only:
            b = steady_propagation(
                eps, h, args.out / f"steady_{tag}", steps=args.steps, skip=args.skip, **options
            )
            row.update(
                {"h_over_eps (b)": round(b["h"] / eps, 4), "elements (b)": b["elements"],
                 "speed_over_V": round(b["speed_ratio"], 4),
                 "toughness_over_g_eff": round(b["toughness_ratio"], 4),
                 "stick_slip": round(b["stick_slip"], 3),
                 "tip_g_drift": round(b["tip_g_drift"], 4),
                 "lead": round(b["lead"], 4), "steady_wall_s": round(b["wall_s"], 1),
                 "steps": args.steps, "skip": args.skip}
            )  # fmt: skip
        rows.append({**row, "eta": args.eta, "am_stop": args.am_stop, **settings})
        print(rows[-1], flush=True)
    args.out.mkdir(parents=True, exist_ok=True)
    with open(args.out / "griffith.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)


if __name__ == "__main__":
    main()
