"""Write the notebooks from their cells (run: python notebooks/make_notebooks.py).

Keeping the source here keeps the .ipynb files free of outputs and easy to review.
"""

from pathlib import Path

import nbformat as nbf

HERE = Path(__file__).parent

COMMON_SETUP = '''\
import os, time
import numpy as np
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
import voxgi

# Small sizes by default (CI runs this notebook top to bottom in about a minute);
# VOXGI_FULL=1 runs the full-size study.
FULL = os.environ.get("VOXGI_FULL", "0") == "1"
print("voxgi", voxgi.__version__, "| full size" if FULL else "| small size (set VOXGI_FULL=1 for full)")'''


def notebook(cells):
    nb = nbf.v4.new_notebook()
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3", "language": "python"}
    nb.cells = [nbf.v4.new_markdown_cell(c[3:]) if c.startswith("md:") else nbf.v4.new_code_cell(c)
                for c in cells]
    return nb


resolution = notebook([
    "md:# Voxel resolution: error and time\n\n"
    "How the voxel resolution trades time for accuracy, on two scenes:\n\n"
    "* the **uniform furnace** (closed sphere, every surface emits `Le` and reflects `rho`), whose "
    "exact radiance is `Le / (1 - rho)` everywhere;\n"
    "* the **Cornell box**, against the finest setting of the sweep (self-convergence), since no "
    "closed form exists.\n\nThe solver's error is measured on the records; the display adds its own "
    "noise, measured separately in `benchmarks/`.",
    COMMON_SETUP,
    "resolutions = [24, 32, 48, 64, 96] if FULL else [12, 16, 24]\n"
    "R = 8 if FULL else 4\nrho, Le = 0.8, 1.0\nrows = []\n"
    "for res in resolutions:\n"
    "    scene = voxgi.scenes.furnace_sphere(albedo=rho, emission=Le)\n"
    "    t0 = time.perf_counter()\n"
    "    vox = voxgi.voxelize(scene, resolution=res)\n"
    "    sol = voxgi.solve(vox, directions=R, shoot_directions=R, progress=False)\n"
    "    dt = time.perf_counter() - t0\n"
    "    front = ~vox.back\n"
    "    err = np.abs(sol.radiance[front, 0] * (1 - rho) / Le - 1)\n"
    "    rows.append((res, len(vox), dt, err.mean(), err.max(), sol.bounces))\n"
    "print(f\"{'res':>5} {'records':>9} {'seconds':>8} {'mean err':>9} {'max err':>9} {'bounces':>7}\")\n"
    "for r in rows:\n"
    "    print(f'{r[0]:5d} {r[1]:9d} {r[2]:8.2f} {r[3]:9.2e} {r[4]:9.2e} {r[5]:7d}')",
    "res_c = [16, 24, 32, 48, 64] if FULL else [8, 12, 16]\n"
    "scene = voxgi.scenes.cornell_box(width=32, height=32)\n"
    "sols = {}\n"
    "for res in res_c:\n"
    "    t0 = time.perf_counter()\n"
    "    vox = voxgi.voxelize(scene, resolution=res)\n"
    "    sol = voxgi.solve(vox, directions=R, shoot_directions=2 * R, progress=False)\n"
    "    sols[res] = (sol, time.perf_counter() - t0)\n"
    "# Compare per object: area-weighted mean radiance of each object's front records.\n"
    "def object_radiance(sol):\n"
    "    v = sol.vox\n"
    "    out = []\n"
    "    for k in range(len(scene.objects)):\n"
    "        m = (v.object_id == k) & ~v.back\n"
    "        out.append((sol.radiance[m] * v.area[m, None]).sum(0) / v.area[m].sum())\n"
    "    return np.array(out)\n"
    "ref = object_radiance(sols[res_c[-1]][0])\n"
    "cb_rows = [(res, len(s.vox), dt, float(np.mean(np.abs(object_radiance(s) - ref) / (ref + 1e-3))))\n"
    "           for res, (s, dt) in sols.items()]\n"
    "for r in cb_rows:\n"
    "    print(f'Cornell res {r[0]:3d}: {r[1]:7d} records, {r[2]:6.2f} s, '\n"
    "          f'mean relative difference of object radiance to res {res_c[-1]}: {r[3]:.2e}')",
    "fig, ax = plt.subplots(1, 2, figsize=(9, 3.5))\n"
    "ax[0].loglog([r[0] for r in rows], [r[3] for r in rows], 'o-', label='furnace mean')\n"
    "ax[0].loglog([r[0] for r in rows], [r[4] for r in rows], 's--', label='furnace max')\n"
    "ax[0].loglog([r[0] for r in cb_rows[:-1]], [r[3] for r in cb_rows[:-1]], '^-', "
    "label='Cornell vs finest')\n"
    "ax[0].set_xlabel('resolution'); ax[0].set_ylabel('relative error'); ax[0].legend()\n"
    "ax[1].loglog([r[1] for r in rows], [r[2] for r in rows], 'o-', label='furnace')\n"
    "ax[1].loglog([r[1] for r in cb_rows], [r[2] for r in cb_rows], '^-', label='Cornell')\n"
    "ax[1].set_xlabel('records'); ax[1].set_ylabel('seconds (voxelize + solve)'); ax[1].legend()\n"
    "fig.tight_layout()\nfig.savefig('resolution_study.png', dpi=80)",
])

directions = notebook([
    "md:# Direction counts and bounce coarsening\n\n"
    "The discrete sphere of radius `R` holds the integer vectors of length `round(|v|) = R` "
    "(R = 8: 762 directions; 22: 5982). More directions cost linearly more time and lower the "
    "error. Later bounces carry smooth light and can use a coarser sphere (Piwowar & Malgouyres "
    "2009): `solve(..., later_directions=r)`.\n\nScenes: the sphere with an emitting cap, whose "
    "exact answer is `L(x) = Le(x) + rho * mean(Le) / (1 - rho)` (uniform form factors inside a "
    "sphere), and the Cornell box against the finest setting.",
    COMMON_SETUP,
    "radii = [4, 6, 8, 12, 16] if FULL else [3, 4, 6]\n"
    "res = 48 if FULL else 20\nrho, Le = 0.8, 1.0\n"
    "scene = voxgi.scenes.cap_sphere(albedo=rho, emission=Le, subdivisions=4)\n"
    "vox = voxgi.voxelize(scene, resolution=res)\n"
    "front = ~vox.back\n"
    "cap = front & (vox.object_id == 0)\n"
    "mean_le = Le * vox.area[cap].sum() / vox.area[front].sum()\n"
    "exact = np.where(vox.object_id == 0, Le, 0.0) + rho * mean_le / (1 - rho)\n"
    "rows = []\n"
    "for R in radii:\n"
    "    t0 = time.perf_counter()\n"
    "    sol = voxgi.solve(vox, directions=R, shoot_directions=2 * R, progress=False)\n"
    "    dt = time.perf_counter() - t0\n"
    "    err = np.abs(sol.radiance[front, 0] / exact[front] - 1)\n"
    "    rows.append((R, sol.stats['directions']['gather']['count'], dt, err.mean(), err.max(),\n"
    "                 sol.stats['gather_rays']))\n"
    "print(f\"{'R':>3} {'dirs':>6} {'seconds':>8} {'mean err':>9} {'max err':>9} {'gather rays':>12}\")\n"
    "for r in rows:\n"
    "    print(f'{r[0]:3d} {r[1]:6d} {r[2]:8.2f} {r[3]:9.2e} {r[4]:9.2e} {r[5]:12,d}')",
    "md:## Coarser later bounces\n\nSame scene, finest radius for the first two bounces, a coarser "
    "one after: the time falls, the error barely moves when the later light is smooth.",
    "R = radii[-1]\ncoarse_rows = []\n"
    "for later in [None] + [r for r in radii if r < R]:\n"
    "    t0 = time.perf_counter()\n"
    "    sol = voxgi.solve(vox, directions=R, shoot_directions=2 * R, later_directions=later,\n"
    "                      progress=False)\n"
    "    dt = time.perf_counter() - t0\n"
    "    err = np.abs(sol.radiance[front, 0] / exact[front] - 1)\n"
    "    coarse_rows.append((later or R, dt, err.mean()))\n"
    "    print(f'later bounces at R={later or R:3d}: {dt:6.2f} s, mean error {err.mean():.2e}')",
    "cbox = voxgi.scenes.cornell_box(width=32, height=32)\n"
    "cvox = voxgi.voxelize(cbox, resolution=48 if FULL else 16)\n"
    "ref = voxgi.solve(cvox, directions=radii[-1], shoot_directions=2 * radii[-1], progress=False)\n"
    "cf = ~cvox.back\n"
    "cb_rows = []\n"
    "for R in radii[:-1]:\n"
    "    t0 = time.perf_counter()\n"
    "    sol = voxgi.solve(cvox, directions=R, shoot_directions=2 * R, progress=False)\n"
    "    dt = time.perf_counter() - t0\n"
    "    w = cvox.area[cf]\n"
    "    err = np.sum(w * np.abs(sol.radiance[cf, 1] - ref.radiance[cf, 1])) / np.sum(w * ref.radiance[cf, 1])\n"
    "    cb_rows.append((R, dt, err))\n"
    "    print(f'Cornell R={R:3d}: {dt:6.2f} s, area-weighted relative difference to R={radii[-1]}: {err:.2e}')",
    "fig, ax = plt.subplots(1, 2, figsize=(9, 3.5))\n"
    "ax[0].loglog([r[1] for r in rows], [r[3] for r in rows], 'o-', label='cap sphere mean')\n"
    "ax[0].loglog([r[1] for r in rows], [r[4] for r in rows], 's--', label='cap sphere max')\n"
    "ax[0].set_xlabel('directions'); ax[0].set_ylabel('relative error'); ax[0].legend()\n"
    "ax[1].plot([r[0] for r in coarse_rows], [r[1] for r in coarse_rows], 'o-')\n"
    "ax[1].set_xlabel('radius of later bounces'); ax[1].set_ylabel('seconds')\n"
    "fig.tight_layout()\nfig.savefig('direction_study.png', dpi=80)",
])

nbf.write(resolution, HERE / "voxel_resolution.ipynb")
nbf.write(directions, HERE / "direction_counts.ipynb")
print("wrote", HERE / "voxel_resolution.ipynb", HERE / "direction_counts.ipynb")
