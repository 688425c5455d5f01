"""Out-of-distribution evaluation of every forecaster kind, with scenario-level statistics, and the report.

Every number is measured on the test split of the Gulf set (``dataset.split_scenarios``): releases in
regions and footprints by a method never seen in training or calibration. Cases of one scenario are
strongly correlated, so the scenario is the statistical unit: per-scenario means, percentile
bootstrap 95 % CIs over scenarios, and *paired* bootstrap CIs of the difference between two kinds
(the same scenarios resampled for both).
"""
from __future__ import annotations

import argparse
import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import shapely
from tqdm import tqdm

from . import engine as E
from . import features as F
from .kinds import BASELINE_KINDS, DEFAULT_MODEL, LEARNED_KINDS

REPO = Path(__file__).resolve().parents[2]
COVERAGE_LEVELS = (0.5, 0.8, 0.9, 0.95)


def iou(a, b) -> float:
    """Intersection over union of two areas (repaired first when invalid: a self-touching footprint)."""
    a, b = (valid(g) for g in (a, b))
    overlap = shapely.intersection(a, b).area
    union = a.area + b.area - overlap
    return float(overlap / union) if union > 0 else 0.0


def valid(geometry):
    """``geometry`` itself when valid, else repaired (``make_valid``)."""
    return geometry if geometry.is_valid else shapely.make_valid(geometry)


# ---------------------------------------------------------------------------------------------------
# Statistics across scenarios

def scenario_means(values: np.ndarray, scenario: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(scenario ids, mean of ``values`` per scenario) for values [N, ...] -> [S, ...]."""
    ids = np.unique(scenario)
    return ids, np.array([np.nanmean(values[scenario == s], axis=0) for s in ids])


def bootstrap_ci(per_scenario: np.ndarray, seed: int = 0, n_resamples: int = 2000) -> tuple[float, float, float]:
    """(mean, low, high): percentile 95 % bootstrap of the mean over scenarios."""
    values = np.asarray(per_scenario, float)
    values = values[np.isfinite(values)]
    if len(values) == 0:
        return (math.nan, math.nan, math.nan)
    rng = np.random.default_rng(seed)
    means = values[rng.integers(0, len(values), (n_resamples, len(values)))].mean(axis=1)
    return float(values.mean()), float(np.quantile(means, 0.025)), float(np.quantile(means, 0.975))


def paired_ci(a: np.ndarray, b: np.ndarray, seed: int = 0) -> tuple[float, float, float]:
    """Mean of per-scenario differences a - b with its paired bootstrap 95 % CI."""
    return bootstrap_ci(np.asarray(a, float) - np.asarray(b, float), seed)


# ---------------------------------------------------------------------------------------------------
# Scoring

@dataclass
class Scores:
    """Per case and horizon: IoU, centroid error (km), and the normalised centroid error
    (error / uncertainty_m) for the coverage of the calibrated radius."""

    kinds: list[str]
    horizons_h: tuple
    scenario: np.ndarray                       # [N] scenario id per case
    release: np.ndarray                        # [N] instantaneous / continuous
    iou: dict = field(default_factory=dict)    # kind -> [N, H]
    centroid_km: dict = field(default_factory=dict)
    normalised: dict = field(default_factory=dict)
    seconds: dict = field(default_factory=dict)
    family: np.ndarray | None = None           # [N] forcing family per case (``train.forcing_family``)

    def per_scenario(self, metric: str, kind: str) -> np.ndarray:
        return scenario_means(getattr(self, metric)[kind], self.scenario)[1]     # [S, H]

    def subset(self, keep: np.ndarray) -> "Scores":
        """The cases where ``keep`` is true (e.g. one forcing family)."""
        def cut(values: dict) -> dict:
            return {kind: v[keep] for kind, v in values.items()}
        return Scores(self.kinds, self.horizons_h, self.scenario[keep], self.release[keep], cut(self.iou),
                      cut(self.centroid_km), cut(self.normalised), self.seconds,
                      None if self.family is None else self.family[keep])


def load_correctors(weights_dir: Path, kinds) -> dict:
    from .models import Corrector

    return {k: Corrector.load(Path(weights_dir) / f"{k}.pt") for k in kinds
            if k in LEARNED_KINDS and (Path(weights_dir) / f"{k}.pt").is_file()}


def score(scenarios, kinds, settings: E.Settings, correctors: dict, *, exact: bool = False, held: bool = False,
          stride: int = 2, progress: bool = True, horizons_h=F.HORIZONS_H) -> Scores:
    """Every kind on every case (observation noise draw 0) of ``scenarios``; ``held``: no forcing over
    the horizon (``windows.scenario_cases``)."""
    from .train import forcing_family
    from .windows import scenario_cases

    cases = [c for s in tqdm(scenarios, desc="cases", disable=not progress, leave=False)
             for c in scenario_cases(s, horizons_h, exact=exact, held=held, stride=stride)]
    releases = {s.scenario_id: s.params.get("release", "?") for s in scenarios}
    families = {s.scenario_id: forcing_family(s) for s in scenarios}
    out = Scores(list(kinds), tuple(horizons_h), np.array([c.scenario_id for c in cases]),
                 np.array([releases[c.scenario_id] for c in cases]),
                 family=np.array([families[c.scenario_id] for c in cases]))
    for kind in tqdm(kinds, desc="kinds", disable=not progress, leave=False):
        started = time.process_time()
        corrections = (correctors[kind].corrections([c.obs for c in cases], settings.params) if kind in correctors
                       else [None] * len(cases))
        ious, errors, norm = [], [], []
        for case, correction in zip(cases, corrections):
            forecasts = E.forecast_plane(kind, case.obs, horizons_h, settings, correction, contours=False)
            ious.append([iou(f.geometry, t) for f, t in zip(forecasts, case.truth)])
            err = [float(np.linalg.norm(f.centroid - t.centroid)) for f, t in zip(forecasts, case.truth_shapes)]
            errors.append([e / 1e3 for e in err])
            norm.append([e / max(f.uncertainty_m, 1e-9) for e, f in zip(err, forecasts)])
        out.seconds[kind] = (time.process_time() - started) / max(len(cases), 1)
        out.iou[kind], out.centroid_km[kind], out.normalised[kind] = np.array(ious), np.array(errors), np.array(norm)
    return out


def coverage(scores: Scores, kind: str, level: float) -> np.ndarray:
    """[H] share of cases whose true centroid lies within the nominal ``level`` radius."""
    radius = math.sqrt(-2 * math.log(1 - level))        # in units of uncertainty_m (circular 2-D Gaussian)
    return (scores.normalised[kind] <= radius).mean(axis=0)


# ---------------------------------------------------------------------------------------------------
# Tables

def _ci(ci, digits=3) -> str:
    mean, lo, hi = ci
    return f"{mean:.{digits}f} [{lo:.{digits}f}, {hi:.{digits}f}]"


def metric_table(scores: Scores, metric: str, digits: int, seed: int) -> list[str]:
    head = "| kind | " + " | ".join(f"+{h:g} h" for h in scores.horizons_h) + " |"
    lines = [head, "|---" * (len(scores.horizons_h) + 1) + "|"]
    for kind in scores.kinds:
        per = scores.per_scenario(metric, kind)
        lines.append(f"| {kind} | " + " | ".join(_ci(bootstrap_ci(per[:, j], seed), digits)
                                                 for j in range(len(scores.horizons_h))) + " |")
    return lines


def best_ltc(scores: Scores) -> str | None:
    """The LTC solver with the highest mean IoU (the issue's "best LTC")."""
    ltcs = [k for k in scores.kinds if k.startswith("ltc-")]
    return max(ltcs, key=lambda k: scores.iou[k].mean()) if ltcs else None


def best_kind(scores: Scores) -> str:
    """The kind with the highest mean IoU over every case and horizon."""
    return max(scores.kinds, key=lambda k: scores.iou[k].mean())


def paired_table(scores: Scores, kind: str, references, seed: int) -> list[str]:
    """``kind`` minus each reference: IoU (higher is better) and centroid error (lower is better)."""
    lines = ["| vs | metric | " + " | ".join(f"+{h:g} h" for h in scores.horizons_h) + " |",
             "|---|---" + "|---" * len(scores.horizons_h) + "|"]
    for ref in references:
        if ref == kind or ref not in scores.kinds:
            continue
        for metric, label, digits in (("iou", "IoU", 3), ("centroid_km", "centroid km", 2)):
            a, b = scores.per_scenario(metric, kind), scores.per_scenario(metric, ref)
            cells = []
            for j in range(len(scores.horizons_h)):
                verdict, ci = compare(a[:, j], b[:, j], metric == "iou", seed)
                cells.append(_ci(ci, digits) + (f" **{verdict}**" if verdict in ("better", "worse") else ""))
            lines.append(f"| {ref} | {label} | " + " | ".join(cells) + " |")
    return lines


def compare(a: np.ndarray, b: np.ndarray, higher_is_better: bool, seed: int) -> tuple[str, tuple]:
    """('better' | 'worse' | 'not significantly different', paired CI of a - b)."""
    ci = paired_ci(a, b, seed)
    _, lo, hi = ci
    if (lo > 0) if higher_is_better else (hi < 0):
        return "better", ci
    if (hi < 0) if higher_is_better else (lo > 0):
        return "worse", ci
    return "not significantly different", ci


def losses(scores: Scores, kind: str, seed: int) -> list[str]:
    """Plain sentences: every horizon/metric where ``kind`` is not significantly better than a
    baseline or the LSTM (other LTC solvers are in the paired table)."""
    out = []
    for ref in scores.kinds:
        if ref == kind or ref.startswith("ltc-"):
            continue
        for metric, label, higher in (("iou", "IoU", True), ("centroid_km", "centroid error", False)):
            a, b = scores.per_scenario(metric, kind), scores.per_scenario(metric, ref)
            for j, h in enumerate(scores.horizons_h):
                verdict, ci = compare(a[:, j], b[:, j], higher, seed)
                if verdict != "better":
                    out.append(f"- vs {ref}, {label} at +{h:g} h: {verdict} (difference {_ci(ci, 3)}).")
    return out


def release_table(scores: Scores, seed: int) -> list[str]:
    lines = ["| kind | " + " | ".join(f"{r} IoU +{scores.horizons_h[-1]:g} h" for r in ("instantaneous", "continuous")) + " |",
             "|---|---|---|"]
    for kind in scores.kinds:
        cells = []
        for release in ("instantaneous", "continuous"):
            keep = scores.release == release
            if not keep.any():
                cells.append("—")
                continue
            per = scenario_means(scores.iou[kind][keep, -1], scores.scenario[keep])[1]
            cells.append(f"{_ci(bootstrap_ci(per, seed))} (n={len(per)})")
        lines.append(f"| {kind} | " + " | ".join(cells) + " |")
    return lines


def family_section(given: Scores, held: Scores, seed: int) -> list[str]:
    """Every kind's IoU per forcing family in both modes, and the best LTC against the others in each:
    a pooled mean can hide a family where the networks lose."""
    out = []
    for family in ("steady", "varying"):
        for label, scores in (("forcing over the horizon given", given), ("held", held)):
            if scores.family is None or not (scores.family == family).any():
                continue
            keep = scores.family == family
            part = scores.subset(keep)
            out += [f"### {family.capitalize()} forcing, {label}: {len(np.unique(part.scenario))} scenarios, "
                    f"{len(part.scenario)} cases per horizon", "", "IoU:", "", *metric_table(part, "iou", 3, seed), ""]
            learned = best_ltc(part)
            if learned:
                out += [f"{learned} minus each other kind:", "",
                        *paired_table(part, learned, [k for k in part.kinds if k != learned], seed), ""]
    return out


def reliability_table(scores: Scores) -> list[str]:
    lines = ["| kind | nominal | " + " | ".join(f"+{h:g} h" for h in scores.horizons_h) + " |",
             "|---|---" + "|---" * len(scores.horizons_h) + "|"]
    for kind in scores.kinds:
        for level in COVERAGE_LEVELS:
            lines.append(f"| {kind} | {100 * level:.0f} % | " + " | ".join(f"{100 * c:.0f} %" for c in coverage(scores, kind, level)) + " |")
    return lines


def plot_horizons(scores: Scores, path: Path, title: str) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for kind in scores.kinds:
        style = "-" if kind in LEARNED_KINDS else "--"
        for ax, metric in zip(axes, ("iou", "centroid_km")):
            per = scores.per_scenario(metric, kind)
            ax.plot(scores.horizons_h, per.mean(axis=0), style, marker="o", label=kind)
    axes[0].set(xlabel="horizon (h)", ylabel="IoU (mean over scenarios)", title=title)
    axes[1].set(xlabel="horizon (h)", ylabel="centroid error (km)", title=title)
    axes[0].legend(fontsize=7)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def plot_example(case, forecasters: dict, path: Path) -> None:
    """One case: observations, truth and each kind's forecast at the longest horizon."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 6))

    def draw(geometry, **style):
        for part in F.polygon_parts(geometry):
            x, y = np.asarray(part.exterior.coords).T / 1e3
            ax.plot(x, y, **style)
            style.pop("label", None)

    draw(case.obs.geometries[-1], color="grey", label="latest observation")
    draw(case.truth[-1], color="black", lw=2, label="truth")
    for (kind, out), colour in zip(forecasters.items(), plt.cm.tab10.colors):
        draw(out[-1].geometry, color=colour, label=kind)
        if kind in LEARNED_KINDS:
            draw(out[-1].contour_90, color=colour, ls=":", label=f"{kind} 90 % envelope")
    ax.set(aspect="equal", xlabel="km", ylabel="km", title=f"{case.scenario_id} at +{case.end_h:g} h, forecast +15 h")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


# ---------------------------------------------------------------------------------------------------
# Real data: the DWH composites

def real_dwh_check(weights_dir: Path, kinds, paths) -> list[str]:
    """From the 17 and 19 May composites, forecast 20 May and score against the 20 May composite."""
    from .operational import Forecaster
    from .readers import read_polygons

    observations = sorted((read_polygons(p) for p in paths), key=lambda o: o.time)
    if len(observations) < 3:
        return ["Fewer than three DWH dates given: nothing to forecast."]
    lines = ["| Date | Polygons (repaired) | Area (km²) |", "|---|---|---|"]
    for o in observations:
        lines.append(f"| {o.time:%Y-%m-%d} | {len(o.polygons)} ({len(o.repaired)}) | {F.repaired(o.geometry).area and F.to_plane(F.repaired(o.geometry)).area / 1e6:,.0f} |")
    history, truth = observations[:-1], observations[-1]
    lead_h = (truth.time - history[-1].time).total_seconds() / 3600
    plane = F.SpillPlane.about(F.repaired(truth.geometry))
    truth_plane = plane.to_plane(F.repaired(truth.geometry))
    lines += ["", f"No wind or current is known for these dates, so every kind runs without forcing (the prior "
              f"only spreads). The 20 May composite is {lead_h:g} h after 19 May: every kind forecasts at that lead "
              "(any horizon; past 15 h the learned correction is carried on in proportion to the horizon).", "",
              "| kind | horizon | valid | forecast area (km²) | IoU vs 20 May | centroid error (km) | valid geometry |",
              "|---|---|---|---|---|---|---|"]
    for kind in kinds:
        try:
            f = Forecaster(weights_dir, kind).forecast([o.geometry for o in history], [o.time for o in history],
                                                       horizons_h=(lead_h,))[0]
        except (OSError, ValueError) as exc:
            lines.append(f"| {kind} | — | — | — | no forecast: {exc} | — | — |")
            continue
        g = plane.to_plane(f.geometry)
        lines.append(f"| {kind} | +{f.horizon_h:g} h | {f.valid_time:%d %b %H:%M} | {g.area / 1e6:,.0f} | {iou(g, truth_plane):.3f} | "
                     f"{truth_plane.centroid.distance(g.centroid) / 1e3:.1f} | {g.is_valid} |")
    return lines


# ---------------------------------------------------------------------------------------------------
# The report

def latency_ms(weights_dir: Path, kind: str, repeats: int = 10) -> float:
    """CPU milliseconds of one forecast (16 hourly observations, ensemble and contours included)."""
    from .dataset import load_dataset
    from .operational import Forecaster

    scenario = next(s for s in load_dataset() if len(s) >= 16)
    forecaster = Forecaster(weights_dir, kind)
    args = (scenario.geometries[:16], scenario.times()[:16], scenario.environments()[:16])
    forecaster.forecast(*args)
    started = time.process_time()
    for _ in range(repeats):
        forecaster.forecast(*args)
    return 1e3 * (time.process_time() - started) / repeats


def split_line(split: dict, trained: dict, tests: int) -> str:
    """The split the report is about: the committed set's, and, when the shipped weights record another
    (the set grew after they were trained), theirs, so the report never claims training it did not have."""
    line = (f"Split: {len(split.get('train', []))} training, {len(split.get('val', []))} validation (early stopping and "
            f"calibration) and {tests} test scenarios.")
    if trained and (set(trained.get("train", [])), set(trained.get("val", []))) != \
            (set(split.get("train", [])), set(split.get("val", []))):
        line += (f" The shipped weights were trained on {len(trained.get('train', []))} training and "
                 f"{len(trained.get('val', []))} validation scenarios of an earlier, smaller set (their checkpoints "
                 "record which); the test scenarios are the same, never trained on.")
    return line


def write_report(out_md: Path, img_dir: Path, weights_dir: Path, given: Scores, held: Scores, exact: Scores, calibration: dict,
                 real_lines: list[str], timings: dict, command: str, split: dict, seed: int, example: str | None,
                 trained: dict | None = None) -> str:
    best = best_kind(given)
    learned = best_ltc(given)
    horizons = " / ".join(f"{h:g}" for h in given.horizons_h)
    md = ["# Forecaster report: physics prior + learned correction, out of distribution", "",
          f"Regenerate from a clone with `{command}` (about ten minutes of CPU on one core). All figures below "
          "are measured on the **out-of-distribution test split** of the committed Gulf set: releases in the "
          f"held-out regions and footprints drawn by the held-out method (alpha shape), {len(np.unique(given.scenario))} "
          f"scenarios, {len(given.scenario)} forecast cases per horizon, horizons {horizons} h. "
          "Cells are the mean over scenarios with a percentile bootstrap 95 % CI over scenarios.", "",
          split_line(split, trained, len(np.unique(given.scenario))), "",
          "## Headline", "",
          f"- Best kind on this split by mean IoU: **{best}** with forcing over the horizon, **{best_kind(held)}** "
          f"without it (the latest forcing held); the default `--model`: `{DEFAULT_MODEL}`."]
    if learned:
        md.append(f"- Best LTC solver: **{learned}**; the paired comparisons below are {learned} against every "
                  "other kind, the LSTM included.")
    md += ["", "![IoU and centroid error per horizon](img/forecaster_horizons.png)", "",
           "## IoU, given (erroneous) forcing", "",
           "The forecaster is given wind and current with model-like errors (speed factor, direction bias, "
           "autocorrelated noise; `simulate.FORCING_ERRORS`), over the observations and as a forecast over the horizon.", "",
           *metric_table(given, "iou", 3, seed), "",
           "## Centroid error (km), given forcing", "", *metric_table(given, "centroid_km", 2, seed), ""]
    if learned:
        md += [f"## Paired differences: {learned} minus each other kind", "",
               "Paired bootstrap over scenarios; **better**/**worse** where the 95 % CI excludes zero.", "",
               *paired_table(given, learned, [k for k in given.kinds if k != learned], seed), "",
               f"### Where {learned} does not win (against the baselines and the LSTM)", "",
               *(losses(given, learned, seed) or ["- nowhere: every comparison is significantly better."]), ""]
    held_ltc = best_ltc(held)
    md += ["## Given forcing up to the latest observation only (held over the horizon)", "",
           "The same cases without forcing over the horizon, as the public API is called without `horizon_forcing`: "
           "every kind holds the latest observation's (erroneous) forcing while the real forcing goes on changing "
           "(wind shifts, inertial and tidal current). Calibrated separately (`<kind> held` in `calibration.json`).", "",
           "IoU:", "", *metric_table(held, "iou", 3, seed), "", "Centroid error (km):", "",
           *metric_table(held, "centroid_km", 2, seed), ""]
    if held_ltc:
        md += [f"Paired differences, {held_ltc} minus each other kind (held forcing):", "",
               *paired_table(held, held_ltc, [k for k in held.kinds if k != held_ltc], seed), "",
               f"Where {held_ltc} does not win with held forcing (against the baselines and the LSTM):", "",
               *(losses(held, held_ltc, seed) or ["- nowhere: every comparison is significantly better."]), "",
               "Calibration with held forcing:", "", *reliability_table(held), ""]
    md += ["## With the exact forcing", "",
           "The same cases when the forecaster is given the forcing that moved the oil.", "",
           "IoU:", "", *metric_table(exact, "iou", 3, seed), "", "Centroid error (km):", "",
           *metric_table(exact, "centroid_km", 2, seed), "",
           "## By release type (given forcing)", "", *release_table(given, seed), "",
           "## By forcing family", "",
           "Steady wind and current (the paper's regimes and plain steady drift, as an outside evaluator's "
           "scenarios have) against time-varying forcing (wind shifts and veers, inertial and tidal current): "
           "with steady forcing holding the latest forcing loses nothing, and a slick keeps its velocity.", "",
           *family_section(given, held, seed),
           "## Calibration of `uncertainty_m`", "",
           "Share of test cases whose true centroid lies within the nominal radius "
           "(r = sqrt(-2 ln(1 - p)) x `uncertainty_m`; 2.448 x at 95 %). Calibrated per kind and horizon on every observation "
           f"of the validation split ({calibration.get('calibration_cases', '?')} cases) by the split-conformal "
           "quantile of the normalised centroid errors in each forcing family (steady, varying), the larger kept; the "
           "target at 95 % is 90-98 %.", "",
           *reliability_table(given), ""]
    if example:
        md += ["## One case", "", f"![example]({example})", ""]
    md += ["## Real data: DWH composites 17, 19 -> 20 May 2010", "", *real_lines, "",
           "## Cost", "",
           "CPU time of one forecast (16 hourly observations, ensemble and both contours), one thread:", "",
           "| kind | ms |", "|---|---|", *(f"| {k} | {v:.1f} |" for k, v in timings.items()), "",
           "Training record (from `calibration.json`):", "",
           "| kind | epochs run | best epoch | val MSE | train windows | seconds |", "|---|---|---|---|---|---|"]
    for kind, r in calibration.get("training", {}).items():
        md.append(f"| {kind} | {r['epochs_run']} | {r['best_epoch']} | {r['val_at_best']['mse']:.4f} | "
                  f"{r['train_windows']} | {r['train_seconds']} |")
    out_md.parent.mkdir(parents=True, exist_ok=True)
    out_md.write_text("\n".join(md) + "\n")
    return best


def build_parser(parser=None):
    from .train import WEIGHTS_DIR

    parser = parser or argparse.ArgumentParser(prog="oilspill-forecaster evaluate")
    parser.description = ("Score every forecaster kind on the out-of-distribution test split of the committed Gulf "
                          "set; write a Markdown report and PNG plots.")
    parser.add_argument("--weights", type=Path, default=WEIGHTS_DIR, help="weights directory (default: shipped)")
    parser.add_argument("--dataset", type=Path, help="dataset stem (default: the committed Gulf set)")
    parser.add_argument("--report", type=Path, default=REPO / "docs" / "forecaster-report.md",
                        help="Markdown report to write (default: docs/forecaster-report.md)")
    parser.add_argument("--dwh", type=Path, nargs="*", default=None,
                        help="real DWH polygon files (default: ../shared/data/dwh/*.geojson when present)")
    parser.add_argument("--stride", type=int, default=3, help="score every n-th observation (default 3)")
    parser.add_argument("--seed", type=int, default=0, help="bootstrap seed (default: %(default)s)")
    parser.add_argument("--quiet", action="store_true")
    return parser


def main(argv=None, args=None) -> int:
    import torch

    from . import dataset as D
    from .train import read_calibration

    args = args or build_parser().parse_args(argv)
    torch.set_num_threads(1)
    calibration = read_calibration(args.weights)
    settings = E.Settings.from_calibration(calibration)
    scenarios = D.load_dataset(args.dataset or D.GULF_STEM)
    split = D.split_scenarios(scenarios)
    correctors = load_correctors(args.weights, LEARNED_KINDS)
    kinds = [*correctors, *BASELINE_KINDS]
    progress = not args.quiet
    given = score(split.test, kinds, settings, correctors, stride=args.stride, progress=progress)
    held = score(split.test, kinds, settings, correctors, held=True, stride=args.stride, progress=progress)
    exact = score(split.test, kinds, settings, correctors, exact=True, stride=args.stride, progress=progress)
    img = args.report.parent / "img"
    plot_horizons(given, img / "forecaster_horizons.png", "OOD test, given forcing")
    example = None
    from .windows import scenario_cases

    cases = scenario_cases(split.test[0], stride=8) if split.test else []
    if cases:
        case = cases[len(cases) // 2]
        outs = {}
        for kind in kinds:
            correction = correctors[kind].correction(case.obs, settings.params) if kind in correctors else None
            outs[kind] = E.forecast_plane(kind, case.obs, F.HORIZONS_H, settings, correction)
        plot_example(case, outs, img / "forecaster_example.png")
        example = "img/forecaster_example.png"
    dwh = args.dwh
    if dwh is None:
        default = REPO / ".." / "shared" / "data" / "dwh"
        dwh = sorted(default.glob("dwh-*.geojson")) if default.is_dir() else []
    real_lines = (real_dwh_check(args.weights, kinds, dwh) if dwh else
                  ["The DWH composites are not present (`../shared/data/dwh`); pass `--dwh FILES`."])
    timings = {k: latency_ms(args.weights, k) for k in kinds}
    command = "python -m oilspill_moos.forecaster evaluate" + (" " + " ".join(argv) if argv else "")
    trained = next((c.trained_split for c in correctors.values() if c.trained_split), {})
    best = write_report(args.report, img, args.weights, given, held, exact, calibration, real_lines, timings, command,
                        split.ids(), args.seed, example, trained)
    summary = {"best_kind": best, "iou": {k: given.iou[k].mean(axis=0).round(3).tolist() for k in kinds},
               "centroid_km": {k: given.centroid_km[k].mean(axis=0).round(2).tolist() for k in kinds},
               "coverage95": {k: coverage(given, k, 0.95).round(3).tolist() for k in kinds},
               "held": {"best_kind": best_kind(held), "iou": {k: held.iou[k].mean(axis=0).round(3).tolist() for k in kinds},
                        "centroid_km": {k: held.centroid_km[k].mean(axis=0).round(2).tolist() for k in kinds},
                        "coverage95": {k: coverage(held, k, 0.95).round(3).tolist() for k in kinds}}}
    (Path(args.weights) / "evaluation.json").write_text(json.dumps(summary, indent=1) + "\n")
    print(json.dumps(summary))
    print(f"report written to {args.report}")
    return 0
