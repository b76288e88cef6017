from __future__ import annotations

import subprocess
import sys
from pathlib import Path

from click.testing import CliRunner

from replay.cli import cli

REGRESS = Path(__file__).parents[1] / "data" / "regress"


def test_help_lists_group() -> None:
    result = CliRunner().invoke(cli, ["--help"])
    assert result.exit_code == 0
    assert "Bearing-only SLAM" in result.output


def test_unknown_command_is_usage_error() -> None:
    result = CliRunner().invoke(cli, ["no-such-command"])
    assert result.exit_code == 2


def test_help_does_not_import_heavy_libraries() -> None:
    code = (
        "import sys; from replay.cli import cli\n"
        "try:\n    cli(['--help'])\nexcept SystemExit:\n    pass\n"
        "heavy = ('scipy', 'rerun', 'cv2', 'matplotlib', 'dask', 'gtsam', 'jsonschema', 'numpy')\n"
        "heavy = [m for m in heavy if m in sys.modules]\n"
        "assert not heavy, heavy\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


def test_paper_estimator_does_not_import_gtsam() -> None:
    # gtsam (~0.3 s to import) is paid only by the commands that build a joint map
    code = (
        "import sys, numpy as np\n"
        "from pipeline.estimators import make_estimator\n"
        "from replay.stages import Runner\n"
        "free = dict(prior='impartial', n_r=50, n_l=300, turn_prior_sigma_rad=None,"
        " distance_prior_rel=None, window=None)\n"
        "make_estimator('paper', ['A', 'B'], ('A', 'B'), vision_error_rad=0.05,"
        " rng=np.random.default_rng(0), **free)\n"
        "assert 'gtsam' not in sys.modules\n"
        "make_estimator('joint', ['A', 'B'], ('A', 'B'), vision_error_rad=0.05,"
        " rng=np.random.default_rng(0), **free)\n"
        "assert 'gtsam' in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True, capture_output=True)


def test_processing_a_log_without_look_alikes_does_not_import_scipy(tmp_path: Path) -> None:
    # scipy.optimize (~0.6 s to import) is paid only when landmarks look alike (association)
    # or a simulated truth must be matched to ambiguous names
    log = REGRESS / "unwrapped.mcap"
    code = (
        "import sys\n"
        "from replay.cli import cli\n"
        "try:\n"
        f"    cli(['process', {str(log)!r}, '--summary', {str(tmp_path / 's.json')!r}])\n"
        "except SystemExit as e:\n"
        "    assert e.code in (0, None), e.code\n"
        "assert 'scipy.optimize' not in sys.modules\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "s.json").is_file()
