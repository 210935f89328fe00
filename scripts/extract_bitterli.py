"""Extract Bitterli's Mitsuba interiors from a git mirror and make them renderable.

The scenes (Benedikt Bitterli's "Rendering resources", Mitsuba 0.5 XML; CC0
and CC-BY, each folder with its LICENSE.txt) are third-party data and are
never part of this repository: this script writes them outside it.

For each scene folder of the mirror (a bare git directory holding the
``jgarciapueyo/mitsuba2-transient-scenes`` snapshot) it

1. writes every file the snapshot holds, one by one (``git cat-file``; the
   snapshot lacks files of 4 MiB and more, which are skipped and counted);
2. fills in the meshes the snapshot lacks from Bitterli's own pbrt-v4
   exports of the same scenes, held whole in other public mirrors
   (:data:`MESH_SOURCES`: binary PLY, written as the OBJ the scene names,
   vertex for vertex; a source is used for a scene only where the meshes
   both hold are identical, which the script checks);
3. reports whether the scene is *whole*: every file its ``scene.xml``
   references (meshes, textures, environment maps) is present;
4. applies the small edits Mitsuba 3 needs to load the file, the same file
   that voxgi reads, so that both renderers see the same scene (the original
   is kept as ``scene.original.xml``);
5. for a whole scene, writes the variant that both renderers render:
   ``voxgi.Scene.load(scene.xml)`` (every material as voxgi maps it: diffuse
   part, texture, glossy lobe, glass) saved with ``Scene.save`` as
   ``diffuse/scene.toml`` (the folder's name is historical);
   ``voxgi.mitsuba.to_mitsuba`` exports that same scene to Mitsuba;
6. with ``--partial``, for a scene that lacks meshes or textures (not its
   environment map), writes the scene less the shapes whose mesh is missing,
   each missing bitmap texture replaced by a constant grey 0.5, as a scene
   of its own, ``<name>-partial/diffuse/scene.toml`` (what was left out or
   replaced is listed in ``<name>-partial/OMITTED.txt``; the edited Mitsuba
   file is ``<name>/scene.partial.xml``, beside the meshes it names). It is
   not the author's scene, but both renderers see the same one, so it
   serves a comparison.

Usage::

    python scripts/extract_bitterli.py                       # every scene, to /work/scenes
    python scripts/extract_bitterli.py living-room staircase2 --out /tmp/scenes
    python scripts/extract_bitterli.py kitchen --partial     # the kitchen less its missing meshes
    python scripts/extract_bitterli.py --list                # what the mirror holds
    python scripts/extract_bitterli.py kitchen --mirrors /work/.mirror   # meshes filled in

The mesh sources are bare git directories ``<mirrors>/<owner>+<name>/repo``
of the repositories in :data:`MESH_SOURCES` (``git clone --bare`` does as
well); a source that is absent is skipped and said so.

Exit status 0 when every requested scene was extracted (whole or not).
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

MIRROR = Path("/work/.mirror/jgarciapueyo+mitsuba2-transient-scenes/repo")
OUT = Path("/work/scenes")
MIRRORS = Path("/work/.mirror")

#: Where a mesh the snapshot lacks is found whole: (repository, path of the
#: binary PLY with ``{scene}`` the folder and ``{stem}`` the OBJ's name).
#: Both hold Bitterli's pbrt-v4 exports, whose PLY files carry the Mitsuba
#: OBJs' vertices (position, normal, uv) in the same order and the same
#: triangles.
MESH_SOURCES = (
    ("gonsolo/bitterli", "{scene}/pbrt/models/{stem}.ply"),
    ("CoronaEngine/CoronaResource", "examples/assets/test_pbrt/{scene}/models/{stem}.ply"),
)

#: Bitterli's interiors in the snapshot (the Cornell boxes and the Veach
#: scene are left out: voxgi has its own Cornell box).
SCENES = (
    "bathroom",  # Contemporary Bathroom
    "bathroom2",  # Salle de bain
    "dining-room",  # The Breakfast Room
    "kitchen",  # Country Kitchen
    "living-room",  # The Grey & White Room
    "staircase",  # The Wooden Staircase
    "staircase2",  # Modern Hall
)

#: Edits for Mitsuba 3, as (pattern, replacement, why). The scenes' film sets
#: ``high_quality_edges`` (Mitsuba 0.6's ``highQualityEdges``), which Mitsuba 3
#: rejects as an unused property; it only changes how pixels at the image's
#: border are filtered, which neither renderer needs.
EDITS = (
    (
        re.compile(r'[ \t]*<boolean name="(?:high_quality_edges|highQualityEdges)"[^>]*/>\s*?\n?'),
        "",
        "film: removed high_quality_edges (Mitsuba 3 rejects it)",
    ),
)


def _git(mirror: Path, *args: str, binary: bool = False):
    out = subprocess.run(
        ["git", "-C", str(mirror), *args], capture_output=True, check=False, text=not binary
    )
    return out


def blobs(mirror: Path, folder: str) -> list[tuple[str, str, int | None]]:
    """(path, object id, size or None where the snapshot lacks the object)."""
    res = _git(mirror, "ls-tree", "-r", "-l", "HEAD", f"{folder}/")
    if res.returncode != 0:
        raise SystemExit(f"extract_bitterli: cannot list {folder} in {mirror}: {res.stderr}")
    items = []
    for line in res.stdout.splitlines():
        meta, path = line.split("\t", 1)
        _mode, kind, sha, size = meta.split()
        if kind != "blob":
            continue
        present = _git(mirror, "cat-file", "-e", sha).returncode == 0
        items.append((path, sha, int(size) if present and size != "-" else None))
    return items


def extract(mirror: Path, folder: str, out: Path) -> tuple[int, list[str]]:
    """Write the folder's files under ``out``; returns (files written, paths missing)."""
    written, missing = 0, []
    for path, sha, size in blobs(mirror, folder):
        if size is None:
            missing.append(path)
            continue
        dest = out / path
        if dest.is_file() and dest.stat().st_size == size:
            written += 1
            continue
        data = _git(mirror, "cat-file", "blob", sha, binary=True)
        if data.returncode != 0:
            missing.append(path)
            continue
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = dest.with_name(dest.name + ".part")
        tmp.write_bytes(data.stdout)
        tmp.replace(dest)
        written += 1
    return written, missing


def _read_obj(path: Path):
    """(vertices, uv, normals, triangles) of an OBJ whose faces index v, vt
    and vn alike (``f a/a/a ...``), as Bitterli's are; None otherwise."""
    import numpy as np

    v, vt, vn, f = [], [], [], []
    for line in path.read_text(encoding="utf-8", errors="replace").splitlines():
        parts = line.split()
        if not parts:
            continue
        if parts[0] == "v":
            v.append(parts[1:4])
        elif parts[0] == "vt":
            vt.append(parts[1:3])
        elif parts[0] == "vn":
            vn.append(parts[1:4])
        elif parts[0] == "f":
            corners = [c.split("/") for c in parts[1:]]
            if len(corners) != 3 or any(len(set(c)) != 1 for c in corners):
                return None
            f.append([int(c[0]) - 1 for c in corners])
    v, vt, vn = (np.asarray(rows, np.float64).reshape(len(rows), -1) for rows in (v, vt, vn))
    return v, vt, vn, np.asarray(f, np.int64).reshape(-1, 3)


def _read_ply(data: bytes):
    """(vertices, uv, normals, triangles) of a binary PLY mesh."""
    import io

    import numpy as np
    import trimesh

    mesh = trimesh.load(io.BytesIO(data), file_type="ply", process=False)
    uv = getattr(mesh.visual, "uv", None)
    uv = np.zeros((len(mesh.vertices), 0)) if uv is None else np.asarray(uv, np.float64)
    normals = np.asarray(mesh.vertex_normals, np.float64)
    return np.asarray(mesh.vertices, np.float64), uv, normals, np.asarray(mesh.faces, np.int64)


def _write_obj(mesh, dest: Path) -> None:
    """``mesh`` (vertices, uv, normals, triangles) as an OBJ whose faces index
    v, vt and vn alike, as the scene's own OBJs do."""
    import numpy as np

    v, uv, n, f = mesh
    lines = [f"v {a:.9g} {b:.9g} {c:.9g}" for a, b, c in v]
    if uv.shape[1] == 2:
        lines += [f"vt {a:.9g} {b:.9g}" for a, b in uv]
    lines += [f"vn {a:.9g} {b:.9g} {c:.9g}" for a, b, c in n]
    tag = "{0}/{0}/{0}" if uv.shape[1] == 2 else "{0}//{0}"
    lines += ["f " + " ".join(tag.format(i + 1) for i in tri) for tri in np.asarray(f)]
    tmp = dest.with_name(dest.name + ".part")
    tmp.write_text("\n".join(lines) + "\n", encoding="utf-8")
    tmp.replace(dest)


def _same_mesh(a, b) -> bool:
    """Whether two meshes (vertices, uv, normals, triangles) have the same
    triangles: their corners' positions and uv (a mesh may keep vertices no
    triangle uses, which an export drops)."""
    import numpy as np

    if a is None or a[3].shape != b[3].shape:
        return False
    same = bool(np.allclose(a[0][a[3]], b[0][b[3]], atol=1e-5))
    if a[1].shape[1] == 2 and b[1].shape[1] == 2:
        same = same and bool(np.allclose(a[1][a[3]], b[1][b[3]], atol=1e-5))
    return same


def fill_meshes(folder: Path, absent: list[str], mirrors: Path) -> list[str]:
    """Write the OBJ meshes of ``absent`` that a :data:`MESH_SOURCES` mirror
    holds; returns a line per source tried. A source serves a scene only if
    the first mesh it shares with the scene's own is identical to it."""
    wanted = [a for a in absent if a.startswith("models/") and a.endswith(".obj")]
    notes = []
    for repo, template in MESH_SOURCES:
        if not wanted:
            break
        mirror = mirrors / repo.replace("/", "+") / "repo"
        if not mirror.is_dir():
            notes.append(f"{repo}: no mirror at {mirror}, skipped")
            continue
        ply = {a: template.format(scene=folder.name, stem=Path(a).stem) for a in wanted}
        held = [
            a for a in wanted if _git(mirror, "cat-file", "-e", f"HEAD:{ply[a]}").returncode == 0
        ]
        if not held:
            continue
        own = sorted(p.relative_to(folder).as_posix() for p in (folder / "models").glob("*.obj"))
        check = None
        for o in own:
            path = template.format(scene=folder.name, stem=Path(o).stem)
            blob = _git(mirror, "show", f"HEAD:{path}", binary=True)
            if blob.returncode == 0 and blob.stdout:
                check = (o, _same_mesh(_read_obj(folder / o), _read_ply(blob.stdout)))
                break
        if check is None or not check[1]:
            why = (
                "holds none of the scene's own meshes"
                if check is None
                else f"differs on {check[0]}"
            )
            notes.append(f"{repo}: not used, it {why}")
            continue
        for a in held:
            data = _git(mirror, "show", f"HEAD:{ply[a]}", binary=True)
            if data.returncode != 0 or not data.stdout:
                continue
            _write_obj(_read_ply(data.stdout), folder / a)
            wanted.remove(a)
        notes.append(f"{repo}: {len(held)} meshes (checked identical on {check[0]})")
    return notes


def referenced_files(xml_path: Path) -> list[str]:
    """Relative paths of every ``filename`` the scene file names."""
    root = ET.parse(xml_path).getroot()
    return sorted(
        {
            el.get("value")
            for el in root.iter("string")
            if el.get("name") == "filename" and el.get("value")
        }
    )


def apply_edits(folder: Path) -> list[str]:
    """Edit ``scene.xml`` for Mitsuba 3 (the original kept beside it); returns what changed."""
    xml, orig = folder / "scene.xml", folder / "scene.original.xml"
    if not orig.exists():
        orig.write_bytes(xml.read_bytes())
    text = orig.read_text(encoding="utf-8")
    done = []
    for pattern, repl, why in EDITS:
        text, n = pattern.subn(repl, text)
        if n:
            done.append(f"{why} ({n}x)")
    xml.write_text(text, encoding="utf-8")
    return done


def save_as_loaded(xml: Path, dest: Path) -> Path:
    """``dest/diffuse/scene.toml``: the scene file ``xml`` as voxgi loads it,
    for both renderers; voxgi's load warnings printed."""
    import warnings

    import voxgi

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scene = voxgi.Scene.load(xml)
    for w in caught:
        print(f"    voxgi: {w.message}")
    return scene.save(dest / "diffuse" / "scene.toml")


def write_diffuse(folder: Path) -> Path:
    """``diffuse/scene.toml``: the scene as voxgi loads it, for both renderers."""
    return save_as_loaded(folder / "scene.xml", folder)


#: The constant that stands in for a missing bitmap texture in a partial scene.
STAND_IN_GREY = "0.5"


def write_partial(folder: Path, absent: list[str]) -> Path | None:
    """The scene less its missing meshes, missing textures grey, as ``<folder>-partial``.

    Returns the written ``scene.toml``, or None where a missing file is
    neither a shape's mesh nor a bitmap texture (an environment map: a
    stand-in would change the light itself).
    """
    import shutil

    text = (folder / "scene.xml").read_text(encoding="utf-8")
    root = ET.fromstring(text)
    owners = {}
    for el in root.iter():
        if el.tag in ("shape", "texture"):
            for child in el.findall("string"):
                if child.get("name") == "filename":
                    owners[child.get("value")] = el
    if any(
        a not in owners or owners[a].get("type") not in ("obj", "ply", "bitmap") for a in absent
    ):
        return None
    parents = {child: parent for parent in root.iter() for child in parent}
    notes = []
    for a in absent:
        el = owners[a]
        parent = parents[el]
        if el.tag == "shape":
            parent.remove(el)
            notes.append(f"left out: the shape of {a}\n")
        else:
            grey = ET.Element("spectrum", name=el.get("name", "reflectance"), value=STAND_IN_GREY)
            parent.insert(list(parent).index(el), grey)
            parent.remove(el)
            notes.append(f"replaced by grey {STAND_IN_GREY}: the texture {a}\n")
    dest = folder.with_name(folder.name + "-partial")
    if dest.exists():
        shutil.rmtree(dest)
    dest.mkdir(parents=True)
    # The shapes' relative paths resolve against the scene file's folder:
    # the partial scene file stays beside the original's meshes.
    xml = folder / "scene.partial.xml"
    ET.ElementTree(root).write(xml, encoding="utf-8")
    (dest / "OMITTED.txt").write_text(
        "Files missing from the snapshot, and what the partial scene does instead:\n"
        + "".join(notes)
    )
    return save_as_loaded(xml, dest)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("scenes", nargs="*", help=f"scene folders (default: {' '.join(SCENES)})")
    ap.add_argument("--mirror", type=Path, default=MIRROR, help="bare git directory")
    ap.add_argument("--out", type=Path, default=OUT, help="target folder (outside the repository)")
    ap.add_argument(
        "--mirrors", type=Path, default=MIRRORS, help="folder of the mesh sources' bare mirrors"
    )
    ap.add_argument("--no-diffuse", action="store_true", help="skip the diffuse variant")
    ap.add_argument("--list", action="store_true", help="list the mirror's folders and exit")
    ap.add_argument(
        "--partial",
        action="store_true",
        help="for a scene lacking only meshes, write it less those shapes as <name>-partial",
    )
    args = ap.parse_args(argv)
    if args.list:
        print(_git(args.mirror, "ls-tree", "--name-only", "HEAD").stdout)
        return 0
    whole = []
    for name in args.scenes or SCENES:
        written, missing = extract(args.mirror, name, args.out)
        folder = args.out / name
        if not (folder / "scene.xml").is_file():
            print(f"{name}: no scene.xml ({written} files written)")
            continue
        edits = apply_edits(folder)
        refs = referenced_files(folder / "scene.xml")
        absent = [r for r in refs if not (folder / r).is_file()]
        if absent:
            for note in fill_meshes(folder, absent, args.mirrors):
                print(f"    mesh source {note}")
            absent = [r for r in refs if not (folder / r).is_file()]
        state = "whole" if not absent else f"NOT whole: {len(absent)} referenced files missing"
        print(f"{name}: {written} files, {len(missing)} absent from the snapshot; {state}")
        for r in absent:
            print(f"    missing {r}")
        for e in edits:
            print(f"    edit: {e}")
        if not absent:
            whole.append(name)
            if not args.no_diffuse:
                print(f"    diffuse variant: {write_diffuse(folder)}")
        elif args.partial:
            partial = write_partial(folder, absent)
            print(
                f"    partial variant: {partial}"
                if partial
                else "    no partial variant: a missing file is neither a mesh nor a texture"
            )
    print("whole scenes:", " ".join(whole) if whole else "none")
    return 0


if __name__ == "__main__":
    sys.exit(main())
