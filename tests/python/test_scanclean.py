"""The scanclean Python module against the program: the same library code, the same results.

Run by ctest (tests/python/CMakeLists.txt) with PYTHONPATH = the module's build folder and
SCANCLEAN_PROGRAM / SCANCLEAN_RECORDINGS_DIR set.
"""
import os
import subprocess

import numpy as np
import pytest

import scanclean

PROGRAM = os.environ.get("SCANCLEAN_PROGRAM", "")
RECORDINGS = os.environ.get("SCANCLEAN_RECORDINGS_DIR", "")
BUNNY = os.path.join(RECORDINGS, "bunny", "bun_zipper.ply")
ONI = os.path.join(RECORDINGS, "oni", "3dj_test.oni")


def noisy_sphere(n, seed):
    """n points on a unit-radius sphere with 1 % radial noise, seeded; float32-exact values."""
    rng = np.random.default_rng(seed)
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    p = d * (1.0 + 0.01 * rng.normal(size=(n, 1)))
    return p.astype(np.float32).astype(np.float64), d.astype(np.float32)


def assert_same_clouds(a, b):
    assert sorted(a.keys()) == sorted(b.keys())
    for key in a:
        assert a[key].dtype == b[key].dtype, key
        assert np.array_equal(a[key], b[key]), key


def test_write_read_round_trip_keeps_every_array(tmp_path):
    points, normals = noisy_sphere(500, seed=7)
    rng = np.random.default_rng(8)
    cloud = {
        "points": points,
        "normals": normals,
        "confidences": rng.uniform(size=500).astype(np.float32),
        "colors": rng.integers(0, 256, size=(500, 4), dtype=np.uint8),
        "label": rng.integers(0, 1000, size=500).astype(np.uint32),
        "score": rng.normal(size=500),
    }
    for name in ("c.ply", "c.pcd"):
        scanclean.write(str(tmp_path / name), cloud)
        back = scanclean.read(str(tmp_path / name))
        assert_same_clouds(cloud, back)
    scanclean.write(str(tmp_path / "a.ply"), cloud, ascii=True)
    assert_same_clouds(cloud, scanclean.read(str(tmp_path / "a.ply")))
    scanclean.write(str(tmp_path / "p.pcd"), cloud, provenance="made by test\nDATA x")
    head = (tmp_path / "p.pcd").read_bytes().split(b"\nDATA ")[0]
    assert b"\n# made by test DATA x\n" in head and b"written by scanclean " + \
        scanclean.__version__.encode() in head
    assert_same_clouds(cloud, scanclean.read(str(tmp_path / "p.pcd")))


def test_bad_input_raises_typed_errors(tmp_path):
    with pytest.raises(scanclean.OptionError, match=r"points: expected shape \(N, 3\)"):
        scanclean.robust_filter(np.zeros((4, 2)))
    with pytest.raises(scanclean.OptionError, match="unknown option \"hh\""):
        scanclean.robust_filter(np.zeros((4, 3)), hh=1.0)
    with pytest.raises(scanclean.OptionError, match="tau"):
        scanclean.robust_filter(np.zeros((4, 3)), tau=2.0)
    with pytest.raises(scanclean.OptionError, match=r"normals: expected shape \(4, 3\)"):
        scanclean.robust_filter(np.zeros((4, 3)), normals=np.zeros((3, 3)))
    bad = tmp_path / "bad.ply"
    bad.write_text("ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nend_header\n1\n")
    with pytest.raises(scanclean.InputError, match="bad.ply"):
        scanclean.read(str(bad))
    with pytest.raises(scanclean.Error):
        scanclean.read(str(tmp_path / "missing.ply"))


def test_filter_on_arrays_projects_noise_and_accounts_for_every_point():
    points, normals = noisy_sphere(20000, seed=3)
    phases = []
    r = scanclean.robust_filter(points, normals, progress=lambda p, f: phases.append(p), threads=2)
    s = r["stats"]
    assert s["points_in"] == 20000
    assert s["points_out"] == len(r["points"]) > 15000
    # Invariant of FilterResult: merge counts plus dropped points account for every input point.
    assert int(r["merge_count"].sum()) + len(r["outliers"]["points"]) == 20000
    before = np.abs(np.linalg.norm(points, axis=1) - 1.0).mean()
    after = np.abs(np.linalg.norm(r["points"], axis=1) - 1.0).mean()
    assert after < 0.5 * before, (before, after)
    assert r["flags"].dtype == np.uint8 and r["likelihood"].dtype == np.float32
    assert phases, "progress was never called"
    # Same options, any thread count: bit-identical (robust_filter's contract).
    r1 = scanclean.robust_filter(points, normals, threads=1)
    assert np.array_equal(r1["points"], r["points"])


def test_options_match_the_cpp_defaults_and_are_all_accepted():
    defaults = scanclean.default_filter_options()
    assert defaults["k_h"] == 96 and defaults["scale"] == "auto"
    points, _ = noisy_sphere(3000, seed=5)
    a = scanclean.robust_filter(points, **defaults)
    b = scanclean.robust_filter(points)
    assert np.array_equal(a["points"], b["points"])


@pytest.mark.skipif(not PROGRAM, reason="SCANCLEAN_PROGRAM not set (run through ctest)")
@pytest.mark.parametrize(
    "cli_args,py_options",
    [([], {}), (["--h", "0.002", "--tau", "0.2", "--merge-eps", "0"],
                {"h": 0.002, "tau": 0.2, "merge_eps": 0.0}),
     (["--orient-normals", "24"], {"orient_k": 24}),
     (["--viewpoint", "0,0,1"], {"orient_k": 96, "orient_viewpoint": (0.0, 0.0, 1.0)})],
)
def test_filter_identical_to_the_program(tmp_path, cli_args, py_options):
    cli_out, cli_outliers = tmp_path / "cli.ply", tmp_path / "cli_outliers.ply"
    subprocess.run([PROGRAM, "filter", BUNNY, "-o", str(cli_out), "--outliers", str(cli_outliers)]
                   + cli_args, check=True, capture_output=True)
    r = scanclean.robust_filter(scanclean.read(BUNNY), **py_options)
    py_out, py_outliers = tmp_path / "py.ply", tmp_path / "py_outliers.ply"
    scanclean.write(str(py_out), r)
    scanclean.write(str(py_outliers), r["outliers"])
    assert_same_clouds(scanclean.read(str(cli_out)), scanclean.read(str(py_out)))
    assert_same_clouds(scanclean.read(str(cli_outliers)), scanclean.read(str(py_outliers)))
    assert r["stats"]["points_in"] == 35947


@pytest.mark.skipif(not os.path.exists(ONI), reason="recordings/oni/3dj_test.oni not found")
def test_open_source_iterates_the_bundled_oni_recording():
    with scanclean.open_source(ONI) as source:
        info = source.info
        frames = [(f.index, f.depth.shape, f.depth.dtype, int((f.depth > 0).sum()), f.K["fx"])
                  for f in source]
    assert info["kind"] == "oni"
    assert len(frames) == info["frame_count"] == 12
    for index, shape, dtype, valid, fx in frames:
        assert shape == (480, 640) and dtype == np.uint16
        assert valid > 100000 and fx > 500
    assert [f[0] for f in frames] == sorted(f[0] for f in frames)


def test_open_source_rejects_unknown_schemes():
    with pytest.raises(scanclean.Error, match="scheme"):
        scanclean.open_source("nosuch://device")


def test_crease_split_through_the_bindings_keeps_an_edge_sharp():
    # A 90-degree edge along y (faces z = 0 for x < 0 and x = 0 for z < 0), 1 % noise, seeded.
    rng = np.random.default_rng(3)
    n = 6000
    u, v = rng.uniform(-0.5, 0, n), rng.uniform(-0.5, 0.5, n)
    a = np.c_[u, v, rng.normal(0, 0.01, n)]
    u, v = rng.uniform(-0.5, 0, n), rng.uniform(-0.5, 0.5, n)
    b = np.c_[rng.normal(0, 0.01, n), v, u]
    points = np.r_[a, b]
    assert scanclean.default_filter_options()["crease_spread"] == 0.0

    def edge_rms(r):
        q = r["points"]
        line = np.hypot(q[:, 0], q[:, 2])
        d = np.minimum(np.where(q[:, 0] <= 0, abs(q[:, 2]), line),
                       np.where(q[:, 2] <= 0, abs(q[:, 0]), line))
        near = (line < r["stats"]["h"]) & (abs(q[:, 1]) < 0.4)
        assert near.sum() > 100
        return np.sqrt((d[near] ** 2).mean())

    plain = scanclean.robust_filter(points)
    split = scanclean.robust_filter(points, crease_spread=1.1)
    assert plain["stats"]["kernels_split"] == 0
    assert split["stats"]["kernels_split"] > 100
    # Measured: 0.00202 against 0.00312.
    assert edge_rms(split) < 0.75 * edge_rms(plain)
    # The scale test's crease test runs with a scale per region only.
    assert split["stats"]["scale_crease_samples"] == 0
    regions = scanclean.robust_filter(points, crease_spread=1.1, scale_regions=96)
    assert regions["stats"]["scale_crease_samples"] > 0
