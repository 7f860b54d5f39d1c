"""A campaign row's run identity is read from the run file's root attributes alone: the same values as the one
reader (open_run) gives, and a file that is no run file is refused in one line."""

import h5py
import pytest

from hilbench.bench.campaign_analysis.synthetic import SyntheticCampaign, write_campaign
from hilbench.common.runfile import RunFileError, open_run
from hilbench.common.runfile.identity import run_identity


def test_identity_is_what_open_run_reads(tmp_path):
    write_campaign(tmp_path / "c", SyntheticCampaign(runs=2, duration=0.2, seed=4, operator="ab"))
    for path in sorted((tmp_path / "c").glob("*.h5")):
        with open_run(path) as run:
            expected = {"run_id": run.uid, "start_time": str(run.start_time), "operator": str(run.meta["operator"]),
                        "axis": run.axis}
        assert run_identity(path) == expected and expected["operator"] == "ab"


def test_a_file_that_is_no_run_file_is_refused(tmp_path):
    with h5py.File(tmp_path / "x.h5", "w") as f:
        f.attrs["schema"] = "something-else"
    with pytest.raises(RunFileError, match=r"x\.h5: not a hilbench run file"):
        run_identity(tmp_path / "x.h5")
    with pytest.raises(RunFileError, match="no such file"):
        run_identity(tmp_path / "missing.h5")
