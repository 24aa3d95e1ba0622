"""A map refused before anything runs is named as the user wrote its path: relative,
through a link, whichever check refuses it (a reader, the cleaning, the plausible units)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from contactbench.harness import cli


def maps(folder: Path) -> dict[str, str]:
    """Maps each refused by another check, by file name -> words of the refusal."""
    rng = np.random.default_rng(0)
    np.save(folder / "flat.npy", np.zeros((32, 32)))
    holed = rng.normal(size=(32, 32))
    holed[3, 3] = np.nan
    np.save(folder / "holed.npy", holed)
    np.save(folder / "steep.npy", rng.normal(size=(32, 32)))
    np.save(folder / "line.npy", np.zeros(5))
    return {"flat.npy": "the map is flat", "holed.npy": "missing (NaN) points and nan='error'",
            "steep.npy": "rms slope", "line.npy": "wrong shape"}


@pytest.mark.parametrize("through_link", [False, True])
def test_a_refused_map_is_named_by_the_path_as_given(tmp_path: Path, through_link: bool,
                                                     monkeypatch: pytest.MonkeyPatch,
                                                     capsys: pytest.CaptureFixture[str]) -> None:
    store = tmp_path / "maps"
    store.mkdir()
    refusals = maps(store)
    monkeypatch.chdir(tmp_path)
    for name, words in refusals.items():
        given = f"maps/{name}"
        if through_link:
            given = f"link-{name}"
            Path(given).symlink_to(store / name)
        code = cli.main(["run", "paper-sweep", "--surface", given, "--length", "1e-3", "--nan", "error",
                         "--solvers", "pk", "--out", f"out-{name}"])
        err = capsys.readouterr().err
        assert code == 2 and f"cannot use surface file '{given}': " in err and words in err, err
        assert str(tmp_path) not in err and len(err.strip().splitlines()) == 1, err
        assert not Path(f"out-{name}").exists()
