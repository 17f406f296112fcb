#!/usr/bin/python3
"""deploy/report on a recorded run (the loopback fig75 run of ctest, HT_LOOPBACK_OUT), and on
broken copies of it (issue 17):
  - every plot exists, is a PNG of the stated size (IHDR) and is not blank (pixel spread);
  - index.html references only files that exist, shows the summary's key figures and up to six
    of the display's frames;
  - a truncated trace.csv, a foreign one and a missing one each give one error line naming the
    file and what is wrong, exit status 1, and the plots that can still be drawn.
Usage: tests/report_test.py SOURCE_DIR   (HT_LOOPBACK_OUT names the run folder)
"""
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile

from png_checks import check, failures, png_size


def not_blank(path):
    import matplotlib.image as mpimg
    img = mpimg.imread(path)
    return float(img[..., :3].std()) > 0.02


def run_report(source, run_dir, out, extra=()):
    r = subprocess.run([os.path.join(source, "deploy", "report"), run_dir, "--out", out,
                        "--width", "900", "--height", "600", *extra],
                       capture_output=True, text=True, timeout=120)
    return r.returncode, r.stdout, r.stderr


def check_phase_names(source):
    """Explore's short phases on a half-width panel (per-object rows, two columns): the phase
    names drawn do not overlap each other."""
    import importlib.machinery
    import importlib.util
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    loader = importlib.machinery.SourceFileLoader("report", os.path.join(source, "deploy",
                                                                         "report"))
    spec = importlib.util.spec_from_loader("report", loader)
    report = importlib.util.module_from_spec(spec)
    loader.exec_module(report)
    rows, t = [], 0.0
    for k in range(1, 4):  # three visits: explore's phases and their lengths
        for phase, length in (("transfer", 0.3), ("press", 0.6), ("slide_x", 0.8),
                              ("slide_y", 0.8), ("release", 0.4), ("press", 0.5)):
            for _ in range(int(length * 100)):
                rows.append({"t_s": t, "phase": f"{phase}@{k}"})
                t += 0.01
    fig, axes = plt.subplots(3, 2, figsize=(9, 6), squeeze=False)
    for ax in axes.flat:
        ax.plot([r["t_s"] for r in rows], [0.0] * len(rows))
        report.shade_phases(ax, rows)
    fig.tight_layout()
    report.thin_phase_names(fig)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    overlaps = drawn = 0
    for ax in fig.axes:
        boxes = sorted((t.get_window_extent(renderer) for t in ax.texts if t.get_visible()),
                       key=lambda b: b.x0)
        drawn += len(boxes)
        overlaps += sum(1 for a, b in zip(boxes, boxes[1:]) if b.x0 < a.x1)
    plt.close(fig)
    check(drawn > 0 and overlaps == 0,
          f"phase names: {drawn} drawn on 6 panels, {overlaps} overlapping (want none)")


def main():
    source = sys.argv[1]
    run = os.environ.get("HT_LOOPBACK_OUT")
    if not run or not os.path.exists(os.path.join(run, "trace.csv")):
        print("report_test: no loopback run (HT_LOOPBACK_OUT)", file=sys.stderr)
        return 1
    tmp = tempfile.mkdtemp(prefix="report_test_")
    try:
        # The whole run.
        out = os.path.join(tmp, "full")
        rc, so, se = run_report(source, run, out)
        check(rc == 0, f"report on a good run exits 0 (got {rc}: {se.strip()})")
        # A fig75 run: no rotation.png (that is fig76's experiment, issue 35).
        expected = ["position_force.png", "loop_period.png", "model_age.png",
                    "remote_steps.png", "network.png"]
        check(not os.path.exists(os.path.join(out, "rotation.png")),
              "no rotation.png for a run without the rotation experiment")
        for name in expected:
            path = os.path.join(out, name)
            check(os.path.exists(path), f"{name} written")
            if os.path.exists(path):
                check(png_size(path) == (900, 600), f"{name} is a 900x600 PNG (got "
                      f"{png_size(path)})")
                check(not_blank(path), f"{name} is not blank")
        page = open(os.path.join(out, "index.html")).read()
        refs = re.findall(r'src="([^"]+)"', page)
        plots = [r for r in refs if "frames/frame_" not in r]
        frames = [r for r in refs if "frames/frame_" in r]
        check(sorted(plots) == sorted(expected), f"index.html shows the plots (got {plots})")
        n_frames = len([f for f in os.listdir(os.path.join(run, "frames"))
                        if f.endswith(".png")]) if os.path.isdir(os.path.join(run, "frames")) else 0
        check(len(frames) == min(6, n_frames),
              f"index.html shows min(6, {n_frames}) of the display's frames (got {len(frames)})")
        for ref in refs:
            check(os.path.exists(os.path.join(out, ref)), f"index.html's {ref} exists")
        check("operator_rate_hz" in page and "remote_step_of_models_p50_us" in page,
              "index.html has the summary's key figures")
        scale = re.search(r"\(([^ ()]+) m per N\)", page)
        if n_frames:
            check(scale is not None and len(scale.group(1).lstrip("0.").replace(".", "")) <= 3,
                  f"the arrow scale is given in 3 significant digits (got "
                  f"{scale.group(1) if scale else None!r})")
        check_phase_names(source)

        # The same run as fig76 draws rotation.png; as an explore run over two objects (phases
        # "...@1", "...@2") it draws one row per object and still exits 0.
        for experiment, phase_of in (("fig76", None),
                                     ("explore", lambda i, n: ("press@1" if i < n // 2
                                                                else "slide_x@2"))):
            copy = os.path.join(tmp, experiment)
            shutil.copytree(run, copy, ignore=shutil.ignore_patterns("*.png", "index.html"))
            with open(os.path.join(copy, "summary.json")) as f:
                s = json.load(f)
            s["experiment"] = experiment
            with open(os.path.join(copy, "summary.json"), "w") as f:
                json.dump(s, f)
            if phase_of is not None:
                with open(os.path.join(copy, "trace.csv")) as f:
                    lines = f.read().splitlines()
                head = lines[0].split(",")
                k = head.index("phase")
                body = [ln.split(",") for ln in lines[1:]]
                for i, cells in enumerate(body):
                    cells[k] = phase_of(i, len(body))
                with open(os.path.join(copy, "trace.csv"), "w") as f:
                    f.write("\n".join([lines[0]] + [",".join(c) for c in body]) + "\n")
            rc, so, se = run_report(source, copy, copy)
            check(rc == 0, f"report on the run as {experiment} exits 0 (got {rc}: {se.strip()})")
            check(os.path.exists(os.path.join(copy, "position_force.png")),
                  f"{experiment}: position_force.png written")
            check(os.path.exists(os.path.join(copy, "rotation.png")) == (experiment == "fig76"),
                  f"{experiment}: rotation.png only for fig76")

        # A truncated trace: the rows that parse are plotted, one error names the file.
        broken = os.path.join(tmp, "truncated")
        shutil.copytree(run, broken, ignore=shutil.ignore_patterns("*.png", "index.html"))
        with open(os.path.join(broken, "trace.csv"), "r+") as f:
            text = f.read()
            f.seek(0)
            f.write(text[: len(text) // 2 + 7])
            f.truncate()
        rc, so, se = run_report(source, broken, os.path.join(tmp, "truncated_out"))
        check(rc == 1, f"a truncated trace exits 1 (got {rc})")
        check("trace.csv" in se and "truncated" in se, f"the error names the file ({se!r})")
        check(os.path.exists(os.path.join(tmp, "truncated_out", "position_force.png")),
              "a truncated trace is still plotted")

        # A foreign trace (another program's CSV): no trace plots, the others still written.
        foreign = os.path.join(tmp, "foreign")
        shutil.copytree(run, foreign, ignore=shutil.ignore_patterns("*.png", "index.html"))
        with open(os.path.join(foreign, "trace.csv"), "w") as f:
            f.write("time,voltage\n0,1\n1,2\n")
        rc, so, se = run_report(source, foreign, os.path.join(tmp, "foreign_out"))
        check(rc == 1, f"a foreign trace exits 1 (got {rc})")
        check("trace.csv" in se and "not a trace" in se, f"the error says so ({se!r})")
        check(not os.path.exists(os.path.join(tmp, "foreign_out", "position_force.png")),
              "a foreign trace draws no trace plot")
        check(os.path.exists(os.path.join(tmp, "foreign_out", "network.png")),
              "the summary's plot is still drawn")
        page = open(os.path.join(tmp, "foreign_out", "index.html")).read()
        for ref in re.findall(r'src="([^"]+)"', page):
            check(os.path.exists(os.path.join(tmp, "foreign_out", ref)),
                  f"foreign: index.html's {ref} exists")

        # A missing trace.
        missing = os.path.join(tmp, "missing")
        shutil.copytree(run, missing, ignore=shutil.ignore_patterns("*.png", "index.html",
                                                                     "trace.csv"))
        rc, so, se = run_report(source, missing, os.path.join(tmp, "missing_out"))
        check(rc == 1 and "trace.csv: missing" in se, f"a missing trace is named ({rc}, {se!r})")

        # Not a folder.
        rc, so, se = run_report(source, os.path.join(tmp, "nowhere"), os.path.join(tmp, "x"))
        check(rc == 2 and "not a folder" in se, f"a bad run folder exits 2 ({rc}, {se!r})")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"report_test: {len(failures)} failure(s)")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
