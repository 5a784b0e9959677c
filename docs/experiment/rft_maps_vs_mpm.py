"""Robot speed against leg curvature, MPM against RFT with the sand's own stress maps, on one
chart (docs/experiment.md, "RFT with the sand's stress maps against MPM").

Reads two tables of runs (curvature_per_r, frequency_hz, mean_speed_m_s per run):

- MPM: docs/experiment/leg_curvature_1cm_20261207_runs.csv, the leg-curvature experiment at
  the scene's 1 cm grid (three starts per point; mean and standard error over starts);
- RFT: docs/experiment/leg_curvature_rft_maps_20261207_runs.csv, the output of
  `sandstep experiment config/experiments/leg_curvature_rft_maps.yaml` (its results.csv, five
  starts per point; RFT on flat ground gives the same speed from every start).

Usage, with the Python readers of the tests (tests/python/setup_venv.sh prints the venv's
python; matplotlib installed in it):

    $(tests/python/setup_venv.sh) docs/experiment/rft_maps_vs_mpm.py OUT.png
"""

import collections
import csv
import statistics
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

MPM_RUNS = "docs/experiment/leg_curvature_1cm_20261207_runs.csv"
RFT_RUNS = "docs/experiment/leg_curvature_rft_maps_20261207_runs.csv"
COLOURS = {1.0: "tab:blue", 2.0: "tab:orange", 4.0: "tab:green"}


def speeds(path):
    """(frequency, curvature) -> list of mean speeds (m/s) over the runs of that point."""
    out = collections.defaultdict(list)
    with open(path) as f:
        for row in csv.DictReader(f):
            key = (float(row["frequency_hz"]), float(row["curvature_per_r"]))
            out[key].append(float(row["mean_speed_m_s"]))
    return out


def series(table, frequency):
    """Curvatures, mean speeds and standard errors of one frequency."""
    points = sorted((k, v) for (f, k), v in table.items() if f == frequency)
    ks = [k for k, _ in points]
    means = [statistics.mean(v) for _, v in points]
    errors = [statistics.stdev(v) / len(v) ** 0.5 if len(v) > 1 else 0.0 for _, v in points]
    return ks, means, errors


def main():
    mpm, rft = speeds(MPM_RUNS), speeds(RFT_RUNS)
    fig, ax = plt.subplots(figsize=(7, 4.5))
    for frequency, colour in COLOURS.items():
        ks, means, errors = series(mpm, frequency)
        ax.errorbar(ks, means, yerr=errors, color=colour, marker="o", capsize=3,
                    label=f"MPM, {frequency:g} Hz")
        ks, means, _ = series(rft, frequency)
        ax.plot(ks, means, color=colour, marker="s", linestyle="--",
                label=f"RFT (stress maps), {frequency:g} Hz")
    ax.set_xlabel("leg curvature (1/R): -1 reversed, 0 straight, +1 C-leg")
    ax.set_ylabel("mean speed (m/s)")
    ax.set_title("Speed against leg curvature: MPM (dx 1 cm) and RFT with the sand's maps")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(sys.argv[1], dpi=110)


if __name__ == "__main__":
    main()
