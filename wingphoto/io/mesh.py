"""Point clouds, surface meshes and ParaView time series (PLY / VTK), through meshio.

* :func:`write_point_cloud` - points (and per-point data) as vertices;
* :func:`write_surface` - a triangle mesh (and per-vertex data);
* :func:`write_series` - one mesh per frame plus ParaView's JSON file-series index
  (``<name>.vtu.series``, ``.vtp.series``, ``.vtk.series``, ``.ply.series``), so
  ParaView (5.5 and later) opens the whole sequence as one time-dependent dataset with
  the frame numbers as times. Prefer ``.vtu`` for time series: ParaView's XML readers
  all read the index; numbered ``.ply`` files are also grouped by ParaView's file
  dialog.

The format follows the file's suffix: ``.ply`` (binary PLY), ``.vtu`` (VTK XML
unstructured grid), ``.vtp`` (VTK XML polydata, ASCII, written here: meshio has no .vtp
writer) or ``.vtk`` (legacy VTK). Coordinates
are written as given (mm, left camera frame for wingphoto's 3D points); NaN vertices
are not allowed in a surface (drop the frame) and are dropped from a point cloud.
Every file is written atomically (:func:`wingphoto.io.atomic_write`).
"""
from __future__ import annotations

import json
import logging
import os
import tempfile
from pathlib import Path

import numpy as np

from .atomic import atomic_write

__all__ = ["write_point_cloud", "write_surface", "write_series", "MESH_FORMATS"]

log = logging.getLogger(__name__)

#: Suffix -> meshio file format.
MESH_FORMATS = {".ply": "ply", ".vtu": "vtu", ".vtp": "vtp", ".vtk": "vtk"}


def _format(path):
    fmt = MESH_FORMATS.get(Path(path).suffix.lower())
    if fmt is None:
        raise ValueError(
            f"{path}: unknown mesh format {Path(path).suffix!r}; use one of {', '.join(MESH_FORMATS)}"
        )
    return fmt


def _meshio():
    try:
        import meshio
    except ImportError:  # pragma: no cover - a dependency
        raise ImportError("writing meshes needs meshio: pip install meshio") from None
    return meshio


def _point_data(point_data, n, where):
    out = {}
    for k, v in (point_data or {}).items():
        a = np.asarray(v)
        if a.shape[0] != n:
            raise ValueError(f"point_data[{k!r}] has {a.shape[0]} values but there are {n} {where}")
        out[str(k)] = a.astype(np.float64) if a.dtype.kind in "biuf" else a
    return out


def _vtp_text(points, cells, point_data):
    """VTK XML PolyData (ASCII) of vertices or triangles: meshio does not write .vtp."""
    n = len(points)
    kind, conn = cells
    conn = np.asarray(conn, dtype=np.int64)
    k = conn.shape[1] if conn.size else (1 if kind == "vertex" else 3)
    tag = "Verts" if kind == "vertex" else "Polys"
    nv, npoly = (len(conn), 0) if tag == "Verts" else (0, len(conn))

    def arr(a):
        return " ".join(repr(float(v)) for v in np.ravel(a))

    def iarr(a):
        return " ".join(str(int(v)) for v in np.ravel(a))

    pd_xml = "".join(
        f'        <DataArray type="Float64" Name="{name}" NumberOfComponents="{1 if np.ndim(v) == 1 else np.shape(v)[1]}" '
        f'format="ascii">{arr(v)}</DataArray>\n'
        for name, v in point_data.items()
    )
    return (
        '<?xml version="1.0"?>\n<VTKFile type="PolyData" version="0.1" byte_order="LittleEndian">\n  <PolyData>\n'
        f'    <Piece NumberOfPoints="{n}" NumberOfVerts="{nv}" NumberOfLines="0" NumberOfStrips="0" '
        f'NumberOfPolys="{npoly}">\n'
        f"      <PointData>\n{pd_xml}      </PointData>\n"
        f'      <Points>\n        <DataArray type="Float64" NumberOfComponents="3" format="ascii">{arr(points)}'
        "</DataArray>\n      </Points>\n"
        f"      <{tag}>\n"
        f'        <DataArray type="Int64" Name="connectivity" format="ascii">{iarr(conn)}</DataArray>\n'
        f'        <DataArray type="Int64" Name="offsets" format="ascii">{iarr(np.arange(1, len(conn) + 1) * k)}'
        "</DataArray>\n"
        f"      </{tag}>\n    </Piece>\n  </PolyData>\n</VTKFile>\n"
    )


def _write(mesh, path):
    """Write a meshio mesh through a temporary file, then replace ``path`` atomically."""
    path = Path(path)
    fmt = _format(path)
    if fmt == "vtp":
        cell = mesh.cells[0]
        text = _vtp_text(mesh.points, (cell.type, cell.data), mesh.point_data)
        with atomic_write(path, "w") as f:
            f.write(text)
        return path
    meshio = _meshio()
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        kw = {"binary": True} if fmt in ("ply", "vtk") else {}
        meshio.write(tmp, mesh, file_format=fmt, **kw)
        with open(tmp, "rb") as src, atomic_write(path, "wb") as dst:
            dst.write(src.read())
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def write_point_cloud(path, xyz, point_data=None):
    """Write 3D points as a point cloud (vertices only).

    Parameters
    ----------
    path : str or Path
        ``.ply``, ``.vtu``, ``.vtp`` or ``.vtk``.
    xyz : (N, 3) array_like
        Points, mm; rows with NaN are dropped (with their data).
    point_data : dict of str -> (N,) or (N, k) array_like, optional
        Per-point values (e.g. ``{"point": ids, "sigma_Z": s}``).

    Returns
    -------
    Path

    Examples
    --------
    >>> import tempfile, pathlib, meshio
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "cloud.vtu"
    >>> _ = write_point_cloud(p, [[0, 0, 0], [1, 2, 3], [np.nan, 0, 0]], {"point": [0, 1, 2]})
    >>> m = meshio.read(p); m.points.shape, m.point_data["point"].tolist()
    ((2, 3), [0.0, 1.0])
    """
    meshio = _meshio()
    X = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    data = _point_data(point_data, len(X), "points")
    keep = np.all(np.isfinite(X), axis=1)
    X = X[keep]
    data = {k: v[keep] for k, v in data.items()}
    cells = [("vertex", np.arange(len(X), dtype=np.int64).reshape(-1, 1))]
    return _write(meshio.Mesh(X, cells, point_data=data), path)


def write_surface(path, vertices, faces, point_data=None):
    """Write a triangle mesh.

    Parameters
    ----------
    path : str or Path
        ``.ply``, ``.vtu``, ``.vtp`` or ``.vtk``.
    vertices : (V, 3) array_like
        mm; must be finite.
    faces : (F, 3) array_like of int
        Vertex indices of each triangle.
    point_data : dict, optional
        Per-vertex values.

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        Non-finite vertices, faces that are not triangles or index past the vertices,
        or an unknown suffix.
    """
    meshio = _meshio()
    V = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    F = np.asarray(faces)
    if F.ndim != 2 or F.shape[1] != 3 or F.dtype.kind not in "iu":
        raise ValueError(f"faces must be an (F, 3) array of vertex indices, got shape {F.shape} dtype {F.dtype}")
    if not np.all(np.isfinite(V)):
        raise ValueError(f"{path}: the surface has non-finite vertices; leave that frame out")
    if F.size and (F.min() < 0 or F.max() >= len(V)):
        raise ValueError(f"faces index vertices 0..{len(V) - 1}, got indices {F.min()}..{F.max()}")
    data = _point_data(point_data, len(V), "vertices")
    return _write(meshio.Mesh(V, [("triangle", F.astype(np.int64))], point_data=data), path)


def write_series(folder, items, *, name="series"):
    """Write one mesh per time step and a ParaView index that opens them as a time series.

    Parameters
    ----------
    folder : str or Path
        Output folder (created).
    items : sequence of dict
        One per time step: ``time`` (float, e.g. the frame number), ``vertices`` (V,
        3), ``faces`` ((F, 3) or None for a point cloud), optional ``point_data`` and
        ``name`` (file name inside ``folder``, default ``<name>_<k>.vtu``). All files
        must share one suffix.
    name : str
        Stem of the index file.

    Returns
    -------
    Path
        ``<name>.<ext>.series``, ParaView's JSON file-series index
        (``{"file-series-version": "1.0", "files": [{"name": ..., "time": ...}]}``).

    Examples
    --------
    >>> import tempfile, pathlib, json
    >>> d = pathlib.Path(tempfile.mkdtemp())
    >>> tri = [[0, 1, 2]]
    >>> items = [{"time": t, "vertices": [[0, 0, t], [1, 0, 0], [0, 1, 0]], "faces": tri} for t in (0.0, 1.0)]
    >>> idx = write_series(d, items, name="wing")
    >>> idx.name, [f["name"] for f in json.loads(idx.read_text())["files"]]
    ('wing.vtu.series', ['wing_0000.vtu', 'wing_0001.vtu'])
    """
    folder = Path(folder)
    items = list(items)
    if not items:
        raise ValueError("items is empty: nothing to write")
    files = []
    suffixes = set()
    for k, it in enumerate(items):
        fname = it.get("name") or f"{name}_{k:04d}.vtu"
        suffixes.add(Path(fname).suffix.lower())
        if it.get("faces") is None:
            write_point_cloud(folder / fname, it["vertices"], it.get("point_data"))
        else:
            write_surface(folder / fname, it["vertices"], it["faces"], it.get("point_data"))
        files.append((float(it["time"]), fname))
    if len(suffixes) != 1:
        raise ValueError(f"all files of a series must share one format, got {sorted(suffixes)}")
    index = folder / f"{name}{suffixes.pop()}.series"
    text = json.dumps({"file-series-version": "1.0", "files": [{"name": f, "time": t} for t, f in files]},
                      indent=1) + "\n"
    with atomic_write(index, "w") as f:
        f.write(text)
    return index
