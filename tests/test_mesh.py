"""Mesh writers: point clouds, surfaces and ParaView series read back with meshio."""
import json
import os
import stat

import numpy as np
import pytest

meshio = pytest.importorskip("meshio")

from wingphoto.io.mesh import write_point_cloud, write_series, write_surface  # noqa: E402


def _read(path):
    """meshio.read, or a small VTK XML PolyData reader for .vtp (meshio has none)."""
    if path.suffix != ".vtp":
        return meshio.read(path)
    import xml.etree.ElementTree as ET

    piece = ET.parse(path).getroot().find("PolyData/Piece")
    pts = np.array(piece.find("Points/DataArray").text.split(), float).reshape(-1, 3)
    polys = piece.find("Polys")
    conn = np.array(polys.find("DataArray[@Name='connectivity']").text.split(), int)
    offs = np.array(polys.find("DataArray[@Name='offsets']").text.split(), int)
    assert np.all(np.diff(np.concatenate([[0], offs])) == 3)
    data = {a.get("Name"): np.array(a.text.split(), float) for a in piece.find("PointData")}
    return meshio.Mesh(pts, [("triangle", conn.reshape(-1, 3))], point_data=data)


@pytest.mark.parametrize("suffix", [".ply", ".vtu", ".vtp", ".vtk"])
def test_surface_round_trip(tmp_path, suffix):
    rng = np.random.default_rng(3)
    V = rng.normal(size=(7, 3)) * 10 + [0, 0, 400]
    F = np.array([[0, 1, 2], [2, 3, 4], [4, 5, 6], [0, 2, 6]])
    path = write_surface(tmp_path / f"wing{suffix}", V, F, {"sigma_Z": np.arange(7.0)})
    m = _read(path)
    np.testing.assert_allclose(m.points, V, rtol=1e-6 if suffix == ".ply" else 1e-12)
    tri = [c.data for c in m.cells if c.type == "triangle"]
    np.testing.assert_array_equal(np.concatenate(tri), F)
    np.testing.assert_allclose(np.ravel(m.point_data["sigma_Z"]), np.arange(7.0))


@pytest.mark.parametrize("suffix", [".ply", ".vtu"])
def test_point_cloud_drops_nan_rows(tmp_path, suffix):
    X = np.array([[0, 0, 1.0], [np.nan, 0, 0], [1, 2, 3.0]])
    path = write_point_cloud(tmp_path / f"cloud{suffix}", X, {"point": np.array([5, 6, 7])})
    m = meshio.read(path)
    np.testing.assert_allclose(m.points, X[[0, 2]], rtol=1e-6)
    np.testing.assert_allclose(np.ravel(m.point_data["point"]), [5, 7])


def test_series_index_for_paraview(tmp_path):
    F = np.array([[0, 1, 2]])
    items = [{"time": float(t), "vertices": [[0, 0, t], [1, 0, 0], [0, 1, 0]], "faces": F, "name": f"w_{t:03d}.vtp"}
             for t in (10, 11, 12)]
    idx = write_series(tmp_path / "out", items, name="w")
    assert idx.name == "w.vtp.series"
    spec = json.loads(idx.read_text())
    assert spec["file-series-version"] == "1.0"
    assert [(f["name"], f["time"]) for f in spec["files"]] == [("w_010.vtp", 10.0), ("w_011.vtp", 11.0), ("w_012.vtp", 12.0)]
    for f in spec["files"]:
        assert (tmp_path / "out" / f["name"]).is_file()
    # permissions follow the umask like every other output (no 0600 temp-file leftovers)
    mode = stat.S_IMODE(os.stat(tmp_path / "out" / "w_010.vtp").st_mode)
    assert mode & stat.S_IRUSR and not list((tmp_path / "out").glob(".*tmp*"))
    clouds = write_series(tmp_path / "c", [{"time": 0.0, "vertices": [[0, 0, 0]], "faces": None, "name": "c.ply"}],
                          name="c")
    assert clouds.name == "c.ply.series"


def test_bad_input(tmp_path):
    with pytest.raises(ValueError, match="unknown mesh format '.stl'"):
        write_point_cloud(tmp_path / "x.stl", [[0, 0, 0]])
    with pytest.raises(ValueError, match="non-finite vertices"):
        write_surface(tmp_path / "x.vtu", [[0, 0, np.nan], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    with pytest.raises(ValueError, match=r"faces must be an \(F, 3\) array"):
        write_surface(tmp_path / "x.vtu", np.zeros((3, 3)), [[0.0, 1.0, 2.0]])
    with pytest.raises(ValueError, match="faces index vertices 0..2"):
        write_surface(tmp_path / "x.vtu", np.eye(3), [[0, 1, 3]])
    with pytest.raises(ValueError, match="point_data\\['a'\\] has 2 values but there are 3"):
        write_point_cloud(tmp_path / "x.vtu", np.eye(3), {"a": [1, 2]})
    with pytest.raises(ValueError, match="share one format"):
        write_series(tmp_path, [{"time": 0, "vertices": np.eye(3), "faces": None, "name": "a.vtu"},
                                {"time": 1, "vertices": np.eye(3), "faces": None, "name": "b.ply"}])
    with pytest.raises(ValueError, match="items is empty"):
        write_series(tmp_path, [])
    assert not list(tmp_path.glob("x.*"))  # nothing half-written
