"""``import mat``: a compressed v5 variable is inflated in bounded steps and refused as soon as it inflates beyond its
declared dimensions (a 3.9 MB file drove the importer to 2.27 GB: scipy reads the data at the size its tag says)."""

import resource
import struct
import zlib

import numpy as np
import pytest
from scipy.io import savemat

from hilbench.bench.cli import main
from hilbench.bench.storage import importers
from hilbench.bench.storage.mat5_bound import MatBoundError, check_inflation


def _bomb(path, declared: int, data_bytes: int) -> None:
    """A v5 file: t and torque ordinary, position one compressed matrix of `declared` doubles whose data element
    says (and holds) `data_bytes` bytes of zeros."""
    savemat(path, {"t": np.arange(declared, dtype=float), "torque": np.ones(declared)}, do_compression=True)
    name = b"position"
    body = (struct.pack("<II", 6, 8) + struct.pack("<II", 6, 0)  # array flags: mxDOUBLE_CLASS
            + struct.pack("<II", 5, 8) + struct.pack("<ii", 1, declared)  # dims 1 x declared
            + struct.pack("<II", 1, len(name)) + name.ljust(8, b"\0")  # name
            + struct.pack("<II", 9, data_bytes))  # miDOUBLE data of data_bytes bytes
    z = zlib.compressobj(9)
    stream = z.compress(struct.pack("<II", 14, len(body) + data_bytes) + body)
    block = bytes(1 << 20)
    for _ in range(data_bytes >> 20):
        stream += z.compress(block)
    stream += z.flush()
    with open(path, "ab") as fh:
        fh.write(struct.pack("<II", 15, len(stream)) + stream)


def test_a_compressed_variable_inflating_past_its_dimensions_is_refused_unread(tmp_path):
    src = tmp_path / "bomb.mat"
    _bomb(src, declared=10, data_bytes=256 << 20)  # 10 doubles declared, 256 MiB behind them
    assert src.stat().st_size < 1 << 20
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(importers.ImportDataError, match="position.*inflates beyond"):
        importers.load_mat(src)
    # bounded steps: the peak memory grew by far less than the 256 MiB the file inflates to (ru_maxrss in KiB)
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 64 << 10
    with pytest.raises(MatBoundError):
        check_inflation(str(src), {"position"})
    check_inflation(str(src), {"t", "torque"})  # the bomb is not read when it is not wanted


def test_the_cli_says_it_in_one_line_and_exit_2(tmp_path, capsys):
    src = tmp_path / "bomb.mat"
    _bomb(src, declared=10, data_bytes=16 << 20)
    assert main(["import", "mat", str(src), "-o", str(tmp_path / "out.h5")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "inflates beyond" in err
    assert not (tmp_path / "out.h5").exists()


@pytest.mark.parametrize("complex_", [False, True])
def test_honest_compressed_files_pass_exactly_at_their_size(tmp_path, complex_):
    src = tmp_path / "ok.mat"
    t = np.linspace(0, 1, 5000)
    data = {"t": t, "position": np.sin(t), "torque": np.cos(t), "m": np.ones((7, 3, 2)) * (1 + 1j if complex_ else 1)}
    savemat(src, data, do_compression=True)
    check_inflation(str(src), {"t", "position", "torque", "m"})
    run = importers.load_mat(src)
    assert np.array_equal(run.samples["position"], np.sin(t))
