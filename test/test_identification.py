"""The paper's protocol through the graph, recorded, then identified from the MCAP log."""
from __future__ import annotations

import json

import numpy as np
import pytest

from hasel import paper
from hasel.cli import main as hasel_main
from hasel.lti import tf_freqresp
from hasel.signals import protocol_schedule
from hasel_sysid.chirp import run_chirp


@pytest.fixture(scope="module")
def chirp_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("chirp") / "chirp.mcap"
    sched = protocol_schedule([4.0], repeats=3, precondition_s=0.5)
    run_chirp(sched, str(path), seed=3, quiet=True)
    return path


def test_identify_recovers_paper_plant_from_the_log(chirp_log, tmp_path):
    model_path = tmp_path / "model.json"
    rc = hasel_main(["identify", str(chirp_log), "--json", str(model_path), "--plot", str(tmp_path / "bode.png"),
                     "--report", str(tmp_path / "report")])
    assert rc == 0
    model = json.loads(model_path.read_text())
    f = np.geomspace(0.1, 15.0, 60)
    fit = tf_freqresp(model["num"], model["den"], f)
    ref = tf_freqresp(*paper.plant_tf(), f)
    assert np.max(np.abs(20 * np.log10(np.abs(fit / ref)))) < 1.0  # dB
    assert np.max(np.abs(np.degrees(np.angle(fit / ref)))) < 5.0  # degrees
    p0 = paper.plant_tf()[0][-1] / paper.plant_tf()[1][-1]
    assert model["num"][-1] / model["den"][-1] == pytest.approx(p0, rel=0.02)
    assert (tmp_path / "bode.png").stat().st_size > 10_000
    assert (tmp_path / "report" / "report.md").is_file()


def test_the_log_says_which_chirp_it_used(chirp_log):
    from hasel.io import load_markers

    labels = {(m.label, m.signal) for m in load_markers(chirp_log)}
    assert ("excitation", "paper") in labels and ("precondition", "constant") in labels


def test_chirp_command_rejects_bad_options(capsys):
    assert hasel_main(["chirp", "--offsets", "2,x"]) == 2
    assert hasel_main(["chirp", "--offsets", "8.5"]) == 2  # 8.5 + 1 kV would exceed 9 kV
    assert hasel_main(["chirp", "--duration", "0.0001"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and err.count("error:") == 3
