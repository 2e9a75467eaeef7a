"""catheter-lab diagnose / add: what a person gets, and one-line refusals."""

from pathlib import Path

import pytest

from catheter_models.cli import main

REPO = Path(__file__).resolve().parents[3]
BAG = REPO / "bags" / "model_test_descending_sine"
CLSTM = REPO / "src" / "catheter_control" / "catheter_control" / "data" / "clstm"


def run(argv: list[str]) -> int:
    try:
        main(argv)
    except SystemExit as exc:
        return int(exc.code or 0)
    return 0


def test_a_learned_model_gets_the_residual_tests(tmp_path: Path, capsys) -> None:
    code = run(
        ["diagnose", str(CLSTM), "--train", str(BAG), "--test", str(BAG), "-o", str(tmp_path)]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    assert "residual tests beyond their 95 % band" in out
    assert "has no physical blocks to add: residual tests only" in out
    assert (tmp_path / "residual_tests.png").is_file() and (tmp_path / "diagnosis.json").is_file()


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["add", "friction", str(CLSTM), "-o", "NEW", "--train", str(BAG)], "clstm model"),
        (["add", "creep", str(BAG), "-o", "NEW", "--train", str(BAG)], "not a model directory"),
        (
            ["diagnose", str(CLSTM), "--train", str(BAG), "--test", str(REPO / "bags")],
            "catheter-lab diagnose:",
        ),
    ],
)
def test_refusals_are_one_line(argv: list[str], message: str, tmp_path: Path, capsys) -> None:
    argv = [str(tmp_path / a) if a == "NEW" else a for a in argv]
    assert run(argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1, err
