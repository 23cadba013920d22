"""Survey: each front end alone, where the radar sees it and how strong."""

import json

import numpy as np
import pytest

import rts_scenario.cli as cli
from rts_scenario import RadarProfile, Rig
from rts_scenario.pipeline import Pipeline
from rts_scenario.radar.simulate import ChannelErrors
from rts_scenario.scenario.model import RadarOptions
from rts_scenario.survey import survey


def test_survey_finds_moved_front_ends_and_their_levels():
    rig, radar = Rig.preset("kit-table1"), RadarProfile.preset("paper")
    moved = ChannelErrors(gain_db=np.array([0.0, -1.5, 0.0, 2.0]), phase_deg=np.zeros(4),
                          delay_s=np.zeros(4), az_deg=np.array([0.3, 0.0, -0.2, 0.0]),
                          el_deg=np.array([0.0, 0.25, 0.0, -0.1]), distance_m=np.zeros(4))
    with Pipeline(rig, radar, radar_options=RadarOptions(fidelity="analytic", noise=False),
                  errors=moved) as bench:
        result = survey(rig, radar, bench.play)
    # The FE stands where the error put it; classic CAN carries angles at 0.005 deg.
    np.testing.assert_allclose(result.seen_az_deg, rig.az_deg + moved.az_deg, atol=0.006)
    np.testing.assert_allclose(result.seen_el_deg, rig.el_deg + moved.el_deg, atol=0.006)
    # Levels travel at 0.5 dB steps on classic CAN.
    np.testing.assert_allclose(result.level_db, moved.gain_db, atol=0.26)


def test_survey_command_writes_the_front_ends_as_json(tmp_path, capsys):
    out = tmp_path / "survey.json"
    assert cli.main(["survey", "kit-table1", "--radar", "paper", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert [fe["index"] for fe in data["front_ends"]] == [0, 1, 2, 3]
    first = data["front_ends"][0]
    assert set(first) == {"index", "az_deg", "el_deg", "seen_az_deg", "seen_el_deg", "level_db"}
    assert first["seen_az_deg"] == pytest.approx(first["az_deg"], abs=0.006)
    assert "seen az" in capsys.readouterr().out
