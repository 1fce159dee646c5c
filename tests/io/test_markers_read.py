"""Reference-system marker readers (C3D, TRC, Qualisys TSV) on every real file in
../shared/realdata that carries hand or wrist markers, against independent readers (the `c3d`
package, trc-data-reader) and hand-made files with the quirks real files have."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np
import pytest

from wristtrack.errors import InputError
from wristtrack.io.markers.c3d import read_c3d, write_c3d
from wristtrack.io.markers.read import read_markers
from wristtrack.io.markers.trajectories import MarkerTrajectories
from wristtrack.io.markers.trc import read_trc, write_trc
from wristtrack.io.markers.tsv import read_tsv

pytest.importorskip("ezc3d")
REAL = Path(__file__).resolve().parents[3] / "shared" / "realdata"
KTK, BIO = REAL / "kineticstoolkit", REAL / "biobuddy"

# Every real file with hand or wrist markers: (file, units stored, rate, frames, hand labels).
GLOVES = ("GloveR1", "GloveR2", "GloveR3", "GloveL1", "GloveL2", "GloveL3")
REAL_FILES = [
    (KTK / "kinematics_racing_full.c3d", "m", 69.99, 700,
     (*GLOVES, "RadialStyloidR", "UlnarStyloidR")),
    (KTK / "kinematics_racing_propulsion.c3d", "m", 69.99, 700, GLOVES),
    (KTK / "kinematics_racing_static.c3d", "m", 69.9, 700, GLOVES),
    (KTK / "kinematics_racing_probing_radial_styloid_R.c3d", "m", 69.5, 140, GLOVES),
    (KTK / "kinematics_racing_probing_ulnar_styloid_R.c3d", "m", 69.5, 140, GLOVES),
    (KTK / "kinematics_tennis_serve.c3d", "m", 50.0, 1092,
     ("RWRA", "RWRB", "RFIN", "LWRA", "LWRB", "LFIN")),
    (BIO / "static.c3d", "mm", 100.0, 138, ("RUS", "RRS", "RHMH2", "RHMH5", "LUS", "LRS")),
    (BIO / "anat_pose_ECH.c3d", "mm", 100.0, 875, ("RUS", "RRS", "RHMH2", "RHMH5", "RFT3")),
    (BIO / "static.trc", "m", 100.0, 138, ("RUS", "RRS", "RHMH2", "RHMH5", "LUS", "LRS")),
]

needs_real = pytest.mark.skipif(not REAL.is_dir(), reason=f"{REAL} not beside the repository")


def _independent_c3d(path: Path) -> np.ndarray:
    """(N, K, 3) points in the file's units from the `c3d` package (not ezc3d); NaN where the
    residual marks a gap."""
    import c3d

    with open(path, "rb") as fh, warnings.catch_warnings():
        warnings.simplefilter("ignore")
        reader = c3d.Reader(fh)
        frames = [points for _, points, _ in reader.read_frames()]
    pts = np.stack(frames)  # (N, K, 5): x y z residual cameras
    xyz = pts[:, :, :3].astype(float)
    xyz[pts[:, :, 3] < 0] = np.nan
    return xyz


@needs_real
@pytest.mark.parametrize("path,units,rate,frames,labels", REAL_FILES,
                         ids=[f[0].name for f in REAL_FILES])
def test_every_real_file_with_hand_markers_reads(path, units, rate, frames, labels):
    data = read_markers(path)
    assert data.units == units
    assert data.rate == pytest.approx(rate, abs=0.01)
    assert len(data) == frames and data.times[1] - data.times[0] == pytest.approx(1 / rate, 1e-3)
    for label in labels:
        xyz = data.marker(label)
        assert xyz.shape == (frames, 3)
    # Positions are metres whatever the file stored: a body in a lab is within 10 m.
    finite = data.xyz[np.isfinite(data.xyz)]
    assert finite.size and np.abs(finite).max() < 10.0 and np.abs(finite).max() > 0.1


@needs_real
@pytest.mark.parametrize("name,scale", [("kineticstoolkit/kinematics_tennis_serve.c3d", 1.0),
                                        ("biobuddy/anat_pose_ECH.c3d", 1e-3)])
def test_c3d_agrees_with_an_independent_reader_in_metres(name, scale):
    # (the `c3d` package refuses the racing files' empty ANALOG:SCALE; these two it reads)
    path = REAL / name
    data = read_c3d(path)
    other = _independent_c3d(path) * scale
    assert data.xyz.shape == other.shape
    np.testing.assert_array_equal(np.isnan(data.xyz), np.isnan(other))
    np.testing.assert_allclose(data.xyz, other, atol=1e-6, equal_nan=True)


@needs_real
def test_c3d_gaps_of_the_racing_take_stay_gaps():
    import ezc3d

    path = KTK / "kinematics_racing_propulsion.c3d"
    data = read_c3d(path)
    raw = ezc3d.c3d(str(path))["data"]["points"][:3].transpose(2, 1, 0)  # metres, NaN gaps
    np.testing.assert_array_equal(np.isnan(data.xyz), np.isnan(raw))
    assert 0.15 < np.isnan(data.xyz[:, :, 0]).mean() < 0.3  # 22 % of its points are gaps
    glove = data.select(["GloveR1", "GloveR2", "GloveR3"])
    assert np.isnan(glove).any() and np.isfinite(glove).any()


@needs_real
def test_trc_whose_header_claims_1300_frames_reads_the_138_it_holds():
    import trc

    data = read_trc(BIO / "static.trc")
    assert len(data) == 138
    assert any("1300" in n and "138" in n for n in data.notes)
    oracle = trc.TRCData()
    oracle.load(str(BIO / "static.trc"))
    for label in ("RUS", "RRS", "RHMH2", "RHMH5"):
        np.testing.assert_allclose(data.marker(label), np.array(oracle[label]), atol=1e-12)
    np.testing.assert_allclose(data.times, oracle["Time"])


@needs_real
def test_the_same_static_take_as_c3d_in_mm_and_trc_in_m_agree():
    c3d, trc = read_c3d(BIO / "static.c3d"), read_trc(BIO / "static.trc")
    assert (c3d.units, trc.units) == ("mm", "m")
    for label in ("RUS", "RRS", "RHMH2", "RHMH5"):
        # TRC keeps 5 decimals of a metre: 0.005 mm.
        np.testing.assert_allclose(c3d.marker(label), trc.marker(label), atol=6e-6)


@needs_real
def test_a_subject_prefix_is_optional_and_a_missing_label_is_named():
    data = read_markers(KTK / "kinematics_tennis_serve.c3d")
    np.testing.assert_array_equal(data.marker("RWRA"), data.marker("Derrick:RWRA"))
    np.testing.assert_array_equal(data.marker("rwra"), data.marker("Derrick:RWRA"))
    with pytest.raises(InputError, match="no marker 'WRIST'.*Derrick:RWRA"):
        data.marker("WRIST")


def _traj(n=12, gap=(3, 4)):
    rng = np.random.default_rng(1)
    xyz = rng.normal(0.0, 0.2, (n, 2, 3))
    xyz[list(gap), 1] = np.nan
    return MarkerTrajectories(names=("A", "B"), frames=np.arange(n), times=np.arange(n) / 50.0,
                              xyz=xyz, rate=50.0, irregular=False, source="test")


@pytest.mark.parametrize("units", ["mm", "m"])
def test_our_writers_read_back_with_gaps_kept(tmp_path, units):
    traj = _traj()
    write_trc(tmp_path / "a.trc", traj, units)
    write_c3d(tmp_path / "a.c3d", traj, units)
    for data in (read_trc(tmp_path / "a.trc"), read_c3d(tmp_path / "a.c3d")):
        assert data.labels == ("A", "B") and data.rate == 50.0 and data.units == units
        np.testing.assert_array_equal(np.isnan(data.xyz), np.isnan(traj.xyz))
        np.testing.assert_allclose(data.xyz, traj.xyz, atol=2e-6, equal_nan=True)


TRC_QUIRKS = (
    "PathFileType\t4\t(X/Y/Z)\tq.trc\n"
    "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame\t"
    "OrigNumFrames\n"
    "200\t200\t9\t2\tmm\t200\t1\t9\n"
    "Frame#\tTime\tP\t\t\tQ\n"
    "\t\tX1\tY1\tZ1\tX2\tY2\tZ2\n"
    "\n"
    "1\t0.000\t10\t20\t30\t1\t2\t3\n"
    "2\t0.005\t11\t21\t31\t\t\t\n"  # Q missing: empty cells
    "3\t0.010\t12\t22\t32\n"  # Q missing: cells left out entirely
    "4\t0.015\t0\t0\t0\t4\t5\t6\n"  # P at exactly (0,0,0): a gap
)


def test_trc_quirks_blank_line_short_rows_empty_cells_zeros_and_a_wrong_count(tmp_path):
    path = tmp_path / "q.trc"
    path.write_text(TRC_QUIRKS)
    data = read_trc(path)
    assert len(data) == 4 and data.units == "mm"
    np.testing.assert_allclose(data.marker("P")[0], [0.010, 0.020, 0.030])
    assert np.isnan(data.marker("Q")[1:3]).all() and np.isnan(data.marker("P")[3]).all()
    np.testing.assert_allclose(data.marker("Q")[3], [0.004, 0.005, 0.006])
    assert any("claims 9 frames" in n for n in data.notes)
    assert any("(0, 0, 0)" in n for n in data.notes)


QTM_NEW = (
    "NO_OF_FRAMES\t3\nNO_OF_CAMERAS\t8\nNO_OF_MARKERS\t2\nFREQUENCY\t150\nNO_OF_ANALOG\t0\n"
    "ANALOG_FREQUENCY\t0\nDESCRIPTION\t--\nTIME_STAMP\t2019-03-12, 10:11:12\t123.45\n"
    "DATA_INCLUDED\t3D\nMARKER_NAMES\thand1\thand2\nTRAJECTORY_TYPES\tMeasured\tMeasured\n"
    "Frame\tTime\thand1 X\thand1 Y\thand1 Z\thand2 X\thand2 Y\thand2 Z\n"
    "1\t0.00000\t100.0\t200.0\t300.0\t1.0\t2.0\t3.0\n"
    "2\t0.00667\t101.0\t201.0\t301.0\t0.000\t0.000\t0.000\n"
    "3\t0.01333\t102.0\t202.0\t302.0\t3.0\t4.0\t5.0\n"
)
QTM_OLD = (
    "NO_OF_FRAMES\t2\nNO_OF_CAMERAS\t4\nNO_OF_MARKERS\t1\nFREQUENCY\t100\nNO_OF_ANALOG\t0\n"
    "ANALOG_FREQUENCY\t0\nDESCRIPTION\t--\nTIME_STAMP\t2010-01-01, 00:00:00\n"
    "DATA_INCLUDED\t3D\nMARKER_NAMES\tW\n"
    "500.5\t-20.25\t1000.0\n"
    "501.5\t-21.25\t1001.0\n"
)


def test_qualisys_tsv_new_and_old_layouts(tmp_path):
    (tmp_path / "new.tsv").write_text(QTM_NEW)
    (tmp_path / "old.tsv").write_text(QTM_OLD)
    new, old = read_tsv(tmp_path / "new.tsv"), read_markers(tmp_path / "old.tsv")
    assert new.labels == ("hand1", "hand2") and new.rate == 150.0 and new.units == "mm"
    np.testing.assert_allclose(new.times, [0.0, 1 / 150, 2 / 150])
    np.testing.assert_allclose(new.marker("hand1")[2], [0.102, 0.202, 0.302])
    assert np.isnan(new.marker("hand2")[1]).all()  # QTM writes a lost marker as zeros
    assert old.labels == ("W",) and len(old) == 2
    np.testing.assert_allclose(old.marker("W")[1], [0.5015, -0.02125, 1.001])


@pytest.mark.parametrize("name,text,message", [
    ("x.xyz", "", "unknown reference format .xyz"),
    ("bad.trc", "hello\n", "not a TRC file"),
    ("norate.trc", TRC_QUIRKS.replace("200\t200\t9", "\t\t9"), "no DataRate"),
    ("inches.trc", TRC_QUIRKS.replace("\tmm\t", "\tin\t"), "unknown coordinate units 'in'"),
    ("bad.tsv", "Frame\tTime\n1\t0\n", "not a Qualisys 3-D TSV"),
    ("bad.c3d", "not a c3d", "not a readable C3D"),
])
def test_bad_files_give_one_clear_line(tmp_path, name, text, message):
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(InputError, match=message):
        read_markers(path)


def test_a_missing_file_is_named(tmp_path):
    with pytest.raises(InputError, match="not found"):
        read_markers(tmp_path / "nothing.c3d")
