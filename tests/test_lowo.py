"""The leave-one-world-out tables of ``benchmarks/lowo.py``, redone from a small record."""

import importlib.util
import json
import math
from pathlib import Path

import pytest

SCRIPT = Path(__file__).resolve().parents[1] / "benchmarks" / "lowo.py"


@pytest.fixture(scope="module")
def lowo():
    spec = importlib.util.spec_from_file_location("lowo_script", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def pos(world, model, best="right", rivals=0, family="crop", resolvable=True, mm="right"):
    return {"family": family, "world": world, "other": None, "source": world, "kind": "pos",
            "consensus": {"log10_nfa_model": model, "rivals": rivals, "best": best, "seconds": 0.2},
            "map-merge": {"outcome": mm, "seconds": 0.1}, "resolvable": resolvable,
            "rival_by": "" if resolvable else "consensus search"}


def neg(world, other, model, rivals=0, family="crop"):
    return {"family": family, "world": world, "other": other, "source": f"{world} / {other}",
            "kind": "neg", "consensus": {"log10_nfa_model": model, "rivals": rivals, "best": "wrong",
                                         "seconds": 0.2}}


@pytest.fixture
def record():
    # log10(0.01) = -2: a negative with model m passes the test at offsets below -2 - m
    pairs = [pos("A", -20.0), pos("B", -9.0), pos("C", -3.0), pos("C", -30.0, best="wrong",
                                                                     resolvable=False, mm="refused"),
             neg("A", "B", -5.0), neg("B", "C", -8.0), neg("A", "C", -50.0, rivals=1)]
    return {"max_false_merge": 0.01, "default_offset": 7.5, "peers": ["map-merge"], "pairs": pairs}


def test_offset_is_chosen_without_the_world_left_out(lowo, record):
    ch = lowo.lowo(record["pairs"], 0.01)
    # the whole decision, as the shipped constant is chosen: without A only B-C (-8) is left:
    # it passes up to 6, none passes from 6.25, plus a decade; without C only A-B (-5); without
    # B only A-C, which its rival refuses at any offset: the least offset tried, plus a decade
    assert ch["offsets"] == {"A": 7.25, "B": -19.0, "C": 4.25}
    assert ch["in_sample"] == 7.25
    # on the test alone, A-C (-50) passes up to 48 and sets the offset wherever it is counted
    alone = lowo.lowo(record["pairs"], 0.01, rivals=False)
    assert alone["offsets"] == {"A": 7.25, "B": 49.25, "C": 4.25}
    assert alone["in_sample"] == 49.25
    # the margin is the one given
    assert lowo.lowo(record["pairs"], 0.01, margin=0.25)["in_sample"] == 6.5


def test_world_left_out_is_judged_with_its_own_offset(lowo, record):
    ch = lowo.lowo(record["pairs"], 0.01)
    out = {(r["world"], r["consensus"]["log10_nfa_model"]):
           lowo.consensus_outcome(r, ch["offsets"][r["world"]], 0.01)
           for r in record["pairs"] if r["kind"] == "pos"}
    # A with 7.25: -12.75 <= -2, merged; B with -19: merged; C (-3) with 4.25: refused; the
    # other C pair is merged at the wrong place
    assert out == {("A", -20.0): "right", ("B", -9.0): "right", ("C", -3.0): "refused",
                   ("C", -30.0): "wrong"}


def test_tables_redone_from_a_record(lowo, record, tmp_path, capsys):
    path = tmp_path / "rec.json"
    path.write_text(json.dumps(record))
    assert lowo.main(["--from", str(path)]) == 0
    text = capsys.readouterr().out
    rows = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| ")}
    # out of sample, in sample (7.25), default 7.5, map-merge
    assert rows["**all pairs**"].split("|")[3:7] == [" 2 / 1 / 1 (50 %) ", " 1 / 1 / 2 (25 %) ",
                                                     " 1 / 1 / 2 (25 %) ", " 3 / 0 / 1 (75 %) "]
    assert rows["**resolvable pairs**"].split("|")[2].strip() == "3 (3)"
    assert rows["**resolvable pairs**"].split("|")[3].strip() == "2 / 0 / 1 (67 %)"
    # B-C judged with B left out (-19: merged) and with C left out (4.25: -3.75, merged); A-B
    # with A left out (7.25: refused) and with B left out (merged); A-C never (a rival)
    assert rows["**all**"].split("|")[3].strip() == "3 / 6"
    # the stricter choice on the test alone is tabled too
    assert "passes the test alone" in text and "in sample 49.25" in text
    # the time per pair: 0.2 s against map-merge's 0.1 s in the same run
    assert rows["consensus"].split("|")[2:4] == [" 0.200 ", " 2.00x "]
    # peers taken from an earlier record ran in another process: their seconds are not compared
    record["settings"] = {"peers_from": "earlier.json"}
    path.write_text(json.dumps(record))
    assert lowo.main(["--from", str(path)]) == 0
    text = capsys.readouterr().out
    rows = {line.split("|")[1].strip(): line for line in text.splitlines() if line.startswith("| ")}
    assert rows["consensus"].split("|")[2:4] == [" 0.200 ", " "] and "not compared" in text
    assert "| map-merge | 0.100" not in text


def test_a_record_it_cannot_read_is_one_line_and_exit_2(lowo, tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    assert lowo.main(["--from", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a record" in err[0]


def test_no_offset_clears_a_negative_at_every_decade_refuses_everything(lowo):
    pairs = [pos("A", -500.0), neg("A", "B", -400.0), neg("B", "C", -400.0)]
    ch = lowo.lowo(pairs, 0.01)
    assert math.isinf(ch["offsets"]["A"]) and math.isinf(ch["in_sample"])
    assert lowo.consensus_outcome(pairs[0], ch["offsets"]["A"], 0.01) == "refused"
    assert "in sample inf" in lowo.tables({"max_false_merge": 0.01, "default_offset": 7.5,
                                          "peers": [], "pairs": pairs})


def test_pooled_offsets_are_chosen_on_every_draw_and_the_crop_draws(lowo, tmp_path, capsys):
    d1 = {"max_false_merge": 0.01, "default_offset": 7.5, "peers": [],
          "pairs": [pos("A", -7.0), neg("A", "B", -8.0)]}
    d2 = {"max_false_merge": 0.01, "default_offset": 7.5, "peers": [],
          "pairs": [pos("C", -6.0), neg("B", "C", -5.0)]}
    crops = [{"kind": "pos", "world": "A", "other": None, "right": True, "ambiguous": False,
              "log10_nfa_model": -40.0},
             {"kind": "neg", "world": "A", "other": "C", "right": None, "ambiguous": False,
              "log10_nfa_model": -9.0}]
    paths = []
    for name, d in (("d1", d1), ("d2", d2), ("crops", crops)):
        paths.append(tmp_path / f"{name}.json")
        paths[-1].write_text(json.dumps(d))
    # draw 1 alone has no negative without A: A would be judged with the least offset tried
    assert lowo.lowo(d1["pairs"], 0.01)["offsets"]["A"] == -19.0
    assert lowo.main(["--pooled", str(paths[0]), str(paths[1]), "--crop-records", str(paths[2])]) == 0
    text = capsys.readouterr().out
    # without A: B-C of draw 2 (-5), 4.25; without C: A-B (-8), 7.25; without B: the crop
    # draws' A-C (-9), 8.25, which is also the choice on everything (the shipped rule)
    assert "4.25 to 8.25 decades; A 4.25; C 7.25; every other world and in sample 8.25." in text
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]]
            for line in text.splitlines() if line.startswith("| ")}
    # A's pair: -7 + 4.25 passes; C's: -6 + 7.25 does not; at 8.25 neither
    assert rows["d1"] == ["1 / 1", "0", "1 / 2", "0 / 0"]   # A-B merged with A left out only
    assert rows["d2"] == ["0 / 1", "0", "0 / 2", "0 / 0"]
    assert rows["**all**"] == ["**1 / 2 (50.0 %)**", "0", "1 / 4", "0 / 0"]
    # without the crop draws, B left out has no negative at all
    assert lowo.main(["--pooled", str(paths[0]), str(paths[1])]) == 0
    assert "B -19.00" in capsys.readouterr().out


def test_pooled_records_it_cannot_read_are_one_line_and_exit_2(lowo, tmp_path, capsys):
    bad = tmp_path / "bad.json"
    bad.write_text("[]")
    assert lowo.main(["--pooled", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not records written by --out" in err[0]


def test_a_placement_free_to_slide_is_refused_at_every_offset(lowo, record):
    """A pair whose best placement lies along walls that all run one way (``cross_wall_m``
    under ``ConsensusConfig.cross_wall``) is refused whatever the offset, so it neither sets
    the offset nor counts as placed; records made before the measure never slide."""
    slid = neg("A", "C", -60.0)
    slid["consensus"]["cross_wall_m"] = 0.02
    held = neg("A", "C", -60.0)
    held["consensus"]["cross_wall_m"] = 5.0
    base = lowo.lowo(record["pairs"], 0.01)
    assert lowo.lowo(record["pairs"] + [slid], 0.01) == base
    assert lowo.lowo(record["pairs"] + [held], 0.01)["in_sample"] == 59.25
    assert lowo.lowo(record["pairs"] + [neg("A", "C", -60.0)], 0.01)["in_sample"] == 59.25
    moved = pos("A", -20.0)
    moved["consensus"]["cross_wall_m"] = 0.5
    assert lowo.consensus_outcome(moved, 100.0, 0.01) == "refused"
    assert lowo.consensus_outcome(pos("A", -20.0), -10.0, 0.01) == "right"
    crop = {"kind": "neg", "world": "A", "other": "C", "ambiguous": False,
            "log10_nfa_model": -60.0, "cross_wall_m": 0.3}
    assert lowo.slides(crop) and not lowo.slides(dict(crop, cross_wall_m=3.0))


def test_peers_taken_from_an_earlier_record_of_the_same_draw(lowo):
    """``--peers-from``: the consensus method runs again, the peers' outcomes (and the truth's
    rival, when a peer's placement was it) come from the earlier record of the same pair."""
    earlier = pos("A", -20.0)
    earlier.update(case_seed=7, truth_evidence=100.0, rival_evidence=120.0, rival_by="map-merge",
                   resolvable=False)
    now = pos("A", -21.0, mm="refused")
    now.pop("map-merge")
    now.update(case_seed=7, truth_evidence=100.0, rival_evidence=50.0, rival_by="consensus search",
               resolvable=True)
    other = dict(now, case_seed=8)
    got = lowo.with_earlier_peers(now, {lowo._key(earlier): earlier}, ["map-merge"])
    assert got["map-merge"] == {"outcome": "right", "seconds": 0.1}
    assert got["consensus"]["log10_nfa_model"] == -21.0
    assert got["rival_by"] == "map-merge" and got["resolvable"] is False
    assert "map-merge" not in lowo.with_earlier_peers(other, {lowo._key(earlier): earlier}, ["map-merge"])


def test_peers_from_a_record_of_another_draw_is_one_line_and_exit_2(lowo, record, tmp_path, capsys):
    record["settings"] = {"seed": 3, "crops": 5, "explore": 2, "drift_cases": 2, "drift": 0.01,
                          "drift_theta": 0.001, "repetitive": 6, "splits": [2, 3, 4], "apart": 1,
                          "negatives": 1.0, "quick": False}
    for n, r in enumerate(record["pairs"]):
        r["case_seed"] = n
    prev = tmp_path / "prev.json"
    prev.write_text(json.dumps(record))
    assert lowo.main(["--seed", "1", "--peers-from", str(prev)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "another draw" in err[0] and "seed" in err[0]
    # the record's peers are the ones compared: --peers beside it would be silently replaced
    assert lowo.main(["--seed", "3", "--peers", "map-merge", "--peers-from", str(prev)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "without --peers" in err[0]
    # and --cross-wall on a record made before the one-way check
    assert lowo.main(["--from", str(prev), "--cross-wall", "2"]) == 2
    assert "cross_wall_m" in capsys.readouterr().err


def test_the_refused_pairs_are_classed_by_the_reason_the_method_gives(lowo):
    """``benchmarks/lowo_misses.py`` classes a record's refused resolvable pairs by the reasons
    the consensus method prints, and tables what a start at the truth changed."""
    spec = importlib.util.spec_from_file_location("lowo_misses_script", SCRIPT.parent / "lowo_misses.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    assert mod.refusal("ambiguous: 2 distinct placements fit about as well (90-100% ...") == "rival"
    assert mod.refusal("best placement is not distinguishable from chance: 99% ...") == "chance"
    assert mod.refusal("best placement misses too much: 90 wall cells ...") == "misses"
    assert mod.refusal("best placement is contradicted: 12% of the walls meet ...") == "contradicted"
    assert mod.refusal("the placement may slide: the walls that meet all run one way ...") == "slides"
    rows = [{"class": "chance", "best": "right", "oracle": "refused", "oracle_class": "chance"},
            {"class": "chance", "best": "right", "oracle": "right", "oracle_class": ""},
            {"class": "contradicted", "best": "wrong", "oracle": "refused", "oracle_class": "chance"}]
    text = mod.table(rows)
    assert "| chance | right | 2 | 1 | chance 1 |" in text
    assert "| contradicted | wrong | 1 | 0 | chance 1 |" in text
    assert text.endswith("3 refused resolvable pairs; with the truth as a start 1 placed right.")
    # only resolvable positives the shipped decision refuses are taken
    record = {"max_false_merge": 0.01, "pairs": [
        pos("w", -30.0), pos("w", 5.0), pos("w", 5.0, resolvable=False), neg("w", "v", 5.0)]}
    assert [r["consensus"]["log10_nfa_model"] for r in mod.misses(record)] == [5.0]
