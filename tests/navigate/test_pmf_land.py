"""The tight point-mass filter's reading of missing map nodes: gaps (default) or land."""

import pytest

from jaxgrav.cli import main
from jaxgrav.navigate import TightConfig


def test_tight_config_takes_gaps_or_land():
    assert TightConfig(method="pmf").pmf_missing == "gaps"
    assert TightConfig(method="pmf", pmf_missing="land").pmf_missing == "land"
    with pytest.raises(ValueError, match=r"pmf_missing must be one of .*; got 'sea'"):
        TightConfig(method="pmf", pmf_missing="sea")


@pytest.mark.parametrize("method", ["ukf", "dense", "rbpf"])
def test_missing_is_refused_for_the_other_methods(tmp_path, capsys, method):
    out = tmp_path / "n.csv"
    assert main(["navigate", "--track", str(tmp_path / "log.csv"), "--out", str(out),
                 "--method", method, "--missing", "land"]) == 2
    err = capsys.readouterr().err
    assert "--missing land is for --method pmf" in err and method in err, err
    assert not out.exists()
