"""Write the notebooks from their cells (run: python notebooks/make_notebooks.py).

Keeping the source here keeps the .ipynb files free of outputs and easy to
review. Each notebook leaves its key numbers in a dict named ``summary``,
which ``tests/test_notebooks.py`` checks against known bounds. The prose
beside a table never states a trend the numbers might not show: the code
prints what the numbers say.
"""

import shutil
import subprocess
from pathlib import Path

import nbformat as nbf

HERE = Path(__file__).parent

COMMON_SETUP = '''\
import os
import time

import matplotlib.pyplot as plt
import numpy as np

import voxgi

# Small sizes by default, so that the tests run this notebook in seconds;
# VOXGI_FULL=1 runs the full-size study.
FULL = os.environ.get("VOXGI_FULL", "0") == "1"
print("voxgi", voxgi.__version__, "| full size" if FULL else
      "| small size: the timings below are dominated by fixed costs and mean nothing "
      "(set VOXGI_FULL=1 for the study)")


def trend(values):
    """'falls', 'rises' or 'moves both ways': what a sequence of numbers does."""
    d = np.diff(np.asarray(values, dtype=float))
    if np.all(d < 0):
        return "falls"
    if np.all(d > 0):
        return "rises"
    return "moves both ways"


summary = {}'''


def formatted(code: str) -> str:
    """The cell's code as ruff formats it (with the project's settings), if ruff is here."""
    ruff = shutil.which("ruff")
    if ruff is None:
        return code
    res = subprocess.run(
        [ruff, "format", "--stdin-filename", str(HERE / "cell.py"), "-"],
        input=code,
        capture_output=True,
        text=True,
        check=True,
    )
    return res.stdout.rstrip("\n")


def notebook(cells):
    cells = [cells[0], "%matplotlib inline", *cells[1:]]  # plots inline, under their cell
    nb = nbf.v4.new_notebook()
    nb.metadata["kernelspec"] = {
        "name": "python3",
        "display_name": "Python 3",
        "language": "python",
    }
    nb.cells = [
        nbf.v4.new_markdown_cell(c[3:])
        if c.startswith("md:")
        else nbf.v4.new_code_cell(c if c.startswith("%") else formatted(c))
        for c in cells
    ]
    for i, cell in enumerate(nb.cells):
        cell.id = f"cell-{i}"  # stable ids: regenerating gives the same files
    return nb


resolution = notebook(
    [
        "md:# Voxel resolution: error and time\n\n"
        "How the voxel resolution trades time for accuracy, on two scenes:\n\n"
        "* the **uniform furnace** (a closed sphere whose every surface emits `Le` and reflects "
        "`rho`), whose exact radiance is `Le / (1 - rho)` everywhere (`docs/design.md §1`);\n"
        "* the **Cornell box**, against the finest resolution of the sweep (self-convergence), "
        "since it has no closed form.\n\n"
        "The error is measured on the solve's surface records; the display adds its own noise, "
        "measured in `docs/performance.md`.",
        COMMON_SETUP,
        "md:## The furnace",
        "resolutions = [24, 32, 48, 64, 96] if FULL else [12, 16, 24]\n"
        "R = 8 if FULL else 4\n"
        "rho, Le = 0.8, 1.0\n"
        "exact = Le / (1 - rho)\n"
        "rows = []\n"
        "for res in resolutions:\n"
        "    scene = voxgi.scenes.furnace_sphere(albedo=rho, emission=Le)\n"
        "    t0 = time.perf_counter()\n"
        "    vox = voxgi.voxelize(scene, resolution=res)\n"
        "    sol = voxgi.solve(vox, radius=R, progress=False,\n"
        "                      tuning=voxgi.SolveTuning.paper(shoot_radius=R))\n"
        "    dt = time.perf_counter() - t0\n"
        "    front = ~vox.back\n"
        "    err = np.abs(sol.radiance[front, 0] / exact - 1)\n"
        "    rows.append((res, len(vox), dt, err.mean(), err.max(), sol.bounces))\n"
        'print(f"exact radiance Le / (1 - rho) = {exact:g}")\n'
        "print(f\"{'res':>5} {'records':>9} {'seconds':>8} {'mean err':>9} {'max err':>9} "
        "{'bounces':>7}\")\n"
        "for r in rows:\n"
        "    print(f'{r[0]:5d} {r[1]:9d} {r[2]:8.2f} {r[3]:9.2e} {r[4]:9.2e} {r[5]:7d}')\n"
        "print(f'From resolution {rows[0][0]} to {rows[-1][0]} the mean error '\n"
        "      f'{trend([r[3] for r in rows])} ({rows[0][3]:.2e} to {rows[-1][3]:.2e}) and the '\n"
        "      f'largest {trend([r[4] for r in rows])} ({rows[0][4]:.2e} to {rows[-1][4]:.2e}).')\n"
        "summary['furnace'] = [dict(res=r[0], records=r[1], mean_err=float(r[3]),\n"
        "                           max_err=float(r[4])) for r in rows]",
        "md:## The Cornell box\n\n"
        "Each object's area-weighted mean radiance, against the same at the finest resolution "
        "of the sweep.",
        "res_c = [16, 24, 32, 48, 64] if FULL else [8, 12, 16]\n"
        "scene = voxgi.scenes.cornell_box(width=32, height=32)\n"
        "sols = {}\n"
        "for res in res_c:\n"
        "    t0 = time.perf_counter()\n"
        "    vox = voxgi.voxelize(scene, resolution=res)\n"
        "    sol = voxgi.solve(vox, radius=R, progress=False,\n"
        "                      tuning=voxgi.SolveTuning.paper(shoot_radius=2 * R))\n"
        "    sols[res] = (sol, time.perf_counter() - t0)\n"
        "\n"
        "def object_radiance(sol):\n"
        "    v = sol.vox\n"
        "    out = []\n"
        "    for k in range(len(scene.objects)):\n"
        "        m = (v.object_id == k) & ~v.back\n"
        "        out.append((sol.radiance[m] * v.area[m, None]).sum(0) / v.area[m].sum())\n"
        "    return np.array(out)\n"
        "\n"
        "ref = object_radiance(sols[res_c[-1]][0])\n"
        "cb_rows = [(res, len(s.vox), dt,\n"
        "            float(np.mean(np.abs(object_radiance(s) - ref) / (ref + 1e-3))))\n"
        "           for res, (s, dt) in sols.items()]\n"
        "for r in cb_rows:\n"
        "    print(f'Cornell res {r[0]:3d}: {r[1]:7d} records, {r[2]:6.2f} s, mean relative '\n"
        "          f'difference of object radiance to res {res_c[-1]}: {r[3]:.2e}')\n"
        "coarse = [r[3] for r in cb_rows[:-1]]\n"
        "print(f'Towards the finest resolution the difference {trend(coarse)} '\n"
        "      f'({coarse[0]:.2e} to {coarse[-1]:.2e}).')\n"
        "summary['cornell'] = [dict(res=r[0], records=r[1], rel_diff=r[3]) for r in cb_rows]",
        "fig, ax = plt.subplots(1, 2, figsize=(9, 3.5))\n"
        "ax[0].loglog([r[0] for r in rows], [r[3] for r in rows], 'o-', label='furnace mean')\n"
        "ax[0].loglog([r[0] for r in rows], [r[4] for r in rows], 's--', label='furnace max')\n"
        "ax[0].loglog([r[0] for r in cb_rows[:-1]], [r[3] for r in cb_rows[:-1]], '^-',\n"
        "             label='Cornell vs finest')\n"
        "ax[0].set_xlabel('resolution'); ax[0].set_ylabel('relative error'); ax[0].legend()\n"
        "ax[1].loglog([r[1] for r in rows], [r[2] for r in rows], 'o-', label='furnace')\n"
        "ax[1].loglog([r[1] for r in cb_rows], [r[2] for r in cb_rows], '^-', label='Cornell')\n"
        "ax[1].set_xlabel('records'); ax[1].set_ylabel('seconds (voxelize + solve)')\n"
        "ax[1].legend()\n"
        "fig.tight_layout()\n"
        "plt.show()",
    ]
)

directions = notebook(
    [
        "md:# Direction counts and coarser later bounces\n\n"
        "The discrete sphere of radius `R` holds the integer vectors with `round(|v|) = R` "
        "(R = 8: 762 directions; 22: 5982); the solve's cost grows in proportion to their number "
        "(`docs/design.md §3`, `§7`). Later bounces carry smoother light and can use a coarser "
        "sphere (Piwowar & Malgouyres 2009): "
        "`solve(..., tuning=voxgi.SolveTuning.paper(later_radius=r))`.\n\n"
        "Scenes: the sphere with an emitting cap, whose exact answer is "
        "`L(x) = Le(x) + rho * mean(Le) / (1 - rho)` (every pair of points inside a sphere has the "
        "same form factor), and the Cornell box against its finest setting.",
        COMMON_SETUP,
        "md:## More directions",
        "radii = [4, 6, 8, 12, 16] if FULL else [3, 4, 6]\n"
        "res = 48 if FULL else 20\n"
        "rho, Le = 0.8, 1.0\n"
        "scene = voxgi.scenes.cap_sphere(albedo=rho, emission=Le, subdivisions=4)\n"
        "vox = voxgi.voxelize(scene, resolution=res)\n"
        "front = ~vox.back\n"
        "cap = front & (vox.object_id == 0)\n"
        "mean_le = Le * vox.area[cap].sum() / vox.area[front].sum()\n"
        "exact = np.where(vox.object_id == 0, Le, 0.0) + rho * mean_le / (1 - rho)\n"
        "rows = []\n"
        "for R in radii:\n"
        "    t0 = time.perf_counter()\n"
        "    sol = voxgi.solve(vox, radius=R, progress=False,\n"
        "                      tuning=voxgi.SolveTuning.paper(shoot_radius=2 * R))\n"
        "    dt = time.perf_counter() - t0\n"
        "    err = np.abs(sol.radiance[front, 0] / exact[front] - 1)\n"
        "    n_dirs = sol.stats['directions']['gather']['count']\n"
        "    rows.append((R, n_dirs, dt, err.mean(), err.max(), sol.stats['gather_rays']))\n"
        "print(f\"{'R':>3} {'dirs':>6} {'seconds':>8} {'mean err':>9} {'max err':>9} "
        "{'gather rays':>12}\")\n"
        "for r in rows:\n"
        "    print(f'{r[0]:3d} {r[1]:6d} {r[2]:8.2f} {r[3]:9.2e} {r[4]:9.2e} {r[5]:12,d}')\n"
        "print(f'From R {rows[0][0]} to R {rows[-1][0]} the mean error '\n"
        "      f'{trend([r[3] for r in rows])} '\n"
        "      f'({rows[0][3]:.2e} to {rows[-1][3]:.2e}); the number of gathering rays '\n"
        "      f'{trend([r[5] for r in rows])} ({rows[0][5]:,} to {rows[-1][5]:,}).')\n"
        "summary['cap'] = [dict(R=r[0], directions=r[1], mean_err=float(r[3]),\n"
        "                       max_err=float(r[4])) for r in rows]",
        "md:## Coarser later bounces\n\n"
        "The same scene with the finest radius for the first two bounces and a coarser one "
        "after them, against the finest radius throughout.",
        "R = radii[-1]\n"
        "coarse_rows = []\n"
        "for later in [None] + [r for r in radii if r < R]:\n"
        "    t0 = time.perf_counter()\n"
        "    sol = voxgi.solve(vox, radius=R, progress=False,\n"
        "                      tuning=voxgi.SolveTuning.paper(shoot_radius=2 * R,\n"
        "                                               later_radius=later))\n"
        "    dt = time.perf_counter() - t0\n"
        "    err = np.abs(sol.radiance[front, 0] / exact[front] - 1)\n"
        "    coarse_rows.append((later or R, dt, err.mean()))\n"
        "coarse_rows.sort()  # by the radius of the later bounces\n"
        "for r in coarse_rows:\n"
        "    print(f'later bounces at R={r[0]:3d}: {r[1]:6.2f} s, mean error {r[2]:.2e}')\n"
        "full = coarse_rows[-1]\n"
        "fastest = min(coarse_rows, key=lambda r: r[1])\n"
        "print(f'The finest radius throughout takes {full[1]:.2f} s for a mean error of '\n"
        "      f'{full[2]:.2e}; the fastest setting (later R {fastest[0]}) takes '\n"
        "      f'{fastest[1]:.2f} s for {fastest[2]:.2e}.')\n"
        "summary['later'] = [dict(later_R=r[0], seconds=r[1], mean_err=float(r[2]))\n"
        "                    for r in coarse_rows]",
        "md:## The Cornell box",
        "cbox = voxgi.scenes.cornell_box(width=32, height=32)\n"
        "cvox = voxgi.voxelize(cbox, resolution=48 if FULL else 16)\n"
        "ref = voxgi.solve(cvox, radius=radii[-1], progress=False,\n"
        "                  tuning=voxgi.SolveTuning.paper(shoot_radius=2 * radii[-1]))\n"
        "cf = ~cvox.back\n"
        "w = cvox.area[cf]\n"
        "cb_rows = []\n"
        "for R in radii[:-1]:\n"
        "    t0 = time.perf_counter()\n"
        "    sol = voxgi.solve(cvox, radius=R, progress=False,\n"
        "                      tuning=voxgi.SolveTuning.paper(shoot_radius=2 * R))\n"
        "    dt = time.perf_counter() - t0\n"
        "    err = (np.sum(w * np.abs(sol.radiance[cf, 1] - ref.radiance[cf, 1]))\n"
        "           / np.sum(w * ref.radiance[cf, 1]))\n"
        "    cb_rows.append((R, dt, float(err)))\n"
        "    print(f'Cornell R={R:3d}: {dt:6.2f} s, area-weighted relative difference to '\n"
        "          f'R={radii[-1]} (green): {err:.2e}')\n"
        "summary['cornell'] = [dict(R=r[0], rel_diff=r[2]) for r in cb_rows]",
        "fig, ax = plt.subplots(1, 2, figsize=(9, 3.5))\n"
        "ax[0].loglog([r[1] for r in rows], [r[3] for r in rows], 'o-', label='cap sphere mean')\n"
        "ax[0].loglog([r[1] for r in rows], [r[4] for r in rows], 's--', label='cap sphere max')\n"
        "ax[0].set_xlabel('directions'); ax[0].set_ylabel('relative error'); ax[0].legend()\n"
        "ax[1].plot([r[0] for r in coarse_rows], [r[1] for r in coarse_rows], 'o-')\n"
        "ax[1].set_xlabel('radius of later bounces'); ax[1].set_ylabel('seconds')\n"
        "fig.tight_layout()\n"
        "plt.show()",
    ]
)

display_error = notebook(
    [
        "md:# How far off is each pixel? The display's error estimate\n\n"
        "`voxgi.render` estimates each pixel's standard error from batch means of its frames, "
        "with a guard against heavy tails (`docs/design.md §6`), returns it as "
        "`RenderResult.stderr` and stops when the mean relMSE estimate (single frames inside "
        "surfaces, aligned blocks of 4 frames at edges, where the sub-pixel offsets make frames "
        "cancel) is under `tol` and no "
        "pixel's relative error estimate exceeds `pixel_factor · sqrt(tol)`. Here the estimate "
        "is set beside the error measured against a long render of the same solution (the "
        "estimate is of the display's noise, so the reference keeps the same voxel solution).",
        COMMON_SETUP,
        "size = 256 if FULL else 64\n"
        "res, ref_frames = (64, 512) if FULL else (16, 128)\n"
        "scene = voxgi.scenes.cornell_box(width=size, height=size)\n"
        "vox = voxgi.voxelize(scene, resolution=res)\n"
        "sol = voxgi.solve(vox, progress=False)\n"
        "t0 = time.perf_counter()\n"
        "out = voxgi.render(scene, sol, progress=False)\n"
        "seconds = time.perf_counter() - t0\n"
        "ref = voxgi.render(scene, sol, max_frames=ref_frames, tol=0.0, seed=1000, "
        "progress=False)\n"
        "r = ref.image.astype(np.float64)\n"
        "den = np.sqrt(r * r + 0.01)\n"
        "est_rel = out.stderr / den\n"
        "err_rel = np.abs(out.image - r) / den\n"
        "measured = float(np.mean(err_rel**2)) - ref.stats['est_rel_mse']\n"
        "est = out.stats['est_rel_mse']\n"
        "print(f\"stopped after {out.frames} frames ({out.stats['batches']} batches of \"\n"
        "      f\"{out.stats['batch_frames']}); {out.stats['flagged_pixels']} pixels flagged \"\n"
        "      f\"heavy-tailed, {out.stats['edge_pixels']} at an edge\")\n"
        "print(f'relMSE: estimated {est:.2e}, measured {measured:.2e} '\n"
        "      f'(ratio {est / measured:.2f}); display {seconds:.2f} s')\n"
        "print(f'worst pixel: estimated {est_rel.max():.3f}, measured {err_rel.max():.3f}')\n"
        "summary['cornell'] = dict(frames=out.frames, est=est, measured=measured,\n"
        "                          est_worst=float(est_rel.max()),\n"
        "                          worst=float(err_rel.max()))",
        "md:Left, the estimated relative error of each pixel (mean of the channels); right, the "
        "error measured against the reference, on the same colour scale. A calibrated estimate "
        "shows the same regions, the measured map being one noisy draw of them.",
        "vmax = float(np.quantile(est_rel.mean(axis=2), 0.99))\n"
        "fig, axes = plt.subplots(1, 3, figsize=(12, 4))\n"
        "axes[0].imshow(np.clip(out.image, 0, 1) ** (1 / 2.2))\n"
        "axes[0].set_title(f'image, {out.frames} frames')\n"
        "for ax, m, title in ((axes[1], est_rel, 'estimated relative error'),\n"
        "                     (axes[2], err_rel, 'measured relative error')):\n"
        "    im = ax.imshow(m.mean(axis=2), cmap='magma', vmin=0, vmax=vmax)\n"
        "    ax.set_title(title)\n"
        "    fig.colorbar(im, ax=ax, fraction=0.046)\n"
        "for ax in axes:\n"
        "    ax.set_axis_off()\n"
        "plt.show()",
    ]
)

if __name__ == "__main__":
    nbf.write(resolution, HERE / "voxel_resolution.ipynb")
    nbf.write(directions, HERE / "direction_counts.ipynb")
    nbf.write(display_error, HERE / "display_error.ipynb")
    print(
        "wrote",
        *(HERE / f"{n}.ipynb" for n in ("voxel_resolution", "direction_counts", "display_error")),
    )
