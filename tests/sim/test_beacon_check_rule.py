"""check-beacons' choice among its hypotheses (hw_sim/beaconloc_sim/beacon_check.py
`report`, `most_moved`): the fewest beacons that explain the measurements, unless moving
one more takes off CHI2_PER_BEACON of the total disagreement; ambiguity at a size is no
answer there; sets of fewer than half the beacons. The hypotheses are made up here (the
replays that make real ones: tests/bridge/test_bridge_beacon_check.py)."""
from beaconloc_sim import beacon_check as bc

AS_WRITTEN = [{"section": f"beacon{i}", "chi2": c, "offset_m": [o, 0.0, 0.0],
               "fitted_m": [o, 0.0, 1.0]} for i, (c, o) in enumerate(
                   [(66.9, 0.058), (21.8, 0.030), (124.0, 0.061), (12.0, 0.01)], start=1)]


def hyp(sections, chi2, offset=0.02):
    """A hypothesis moving sections by 0.1 m in x, leaving every beacon chi2 (a list or one
    value for all four)."""
    chi2 = chi2 if isinstance(chi2, list) else [chi2 / 4] * 4
    return bc.Hypothesis(tuple(bc.Move(s, (0.0, 0.0, 1.0), (0.1, 0.0, 1.0)) for s in sections),
                         chi2, [offset] * 4)


def verdict(hyps):
    lines, answer = bc.report(AS_WRITTEN, hyps)
    return lines[-1], answer


def test_single_beacon_kept_when_a_pair_takes_off_little():
    hyps = [hyp(["beacon3"], 20.0), hyp(["beacon1"], 200.0),
            hyp(["beacon1", "beacon3"], 20.0 - bc.CHI2_PER_BEACON + 1)]
    last, answer = verdict(hyps)
    assert [m.section for m in answer.moves] == ["beacon3"]
    assert last.startswith("beacon-check misplaced [beacon3] x_m=0.100 y_m=0.000 z_m=1.000 "
                           "moved_m=0.100")


def test_pair_taken_when_it_takes_off_enough():
    hyps = [hyp(["beacon3"], 80.0), hyp(["beacon1"], 200.0), hyp(["beacon1", "beacon2"], 150.0),
            hyp(["beacon1", "beacon3"], 80.0 - bc.CHI2_PER_BEACON)]
    last, answer = verdict(hyps)
    assert [m.section for m in answer.moves] == ["beacon1", "beacon3"]
    assert last == ("beacon-check misplaced [beacon1] x_m=0.100 y_m=0.000 z_m=1.000 moved_m=0.100 "
                    "[beacon3] x_m=0.100 y_m=0.000 z_m=1.000 moved_m=0.100")


def test_inconsistent_hypotheses_are_no_answer():
    # the pair leaves a beacon over the rule (chi2 > 30 and offset > 3 cm): not taken, however low
    # its total; the single one is
    hyps = [hyp(["beacon3"], 40.0), hyp(["beacon1", "beacon3"], [31.0, 0.0, 0.0, 0.0], offset=0.04)]
    assert not hyps[1].consistent
    assert [m.section for m in verdict(hyps)[1].moves] == ["beacon3"]


def test_ambiguous_size_is_no_answer_there():
    # two singles within CHI2_MARGIN of each other: unresolved naming both, unless a pair clearly
    # explains more
    singles = [hyp(["beacon3"], 40.0), hyp(["beacon1"], 40.0 + bc.CHI2_MARGIN - 1)]
    last, answer = verdict(singles)
    assert answer is None and last.startswith("beacon-check unresolved: [beacon3], [beacon1] each")
    last, answer = verdict(singles + [hyp(["beacon1", "beacon3"], 5.0)])
    assert [m.section for m in answer.moves] == ["beacon1", "beacon3"]
    # and a clear single stays the answer over an ambiguous pair size
    pairs = [hyp(["beacon1", "beacon3"], 5.0), hyp(["beacon2", "beacon3"], 6.0)]
    assert [m.section for m in verdict([singles[0]] + pairs)[1].moves] == ["beacon3"]


def test_nothing_explains():
    last, answer = verdict([hyp(["beacon3"], [40.0, 0, 0, 0], offset=0.05),
                            hyp(["beacon1", "beacon3"], [40.0, 0, 0, 0], offset=0.05)])
    assert answer is None
    assert last.startswith("beacon-check unresolved: no set of up to 2 beacons explains")


def test_consistent_as_written():
    fits = [dict(f, chi2=5.0) for f in AS_WRITTEN]
    lines, answer = bc.report(fits, [])
    assert answer is None and lines[-1].startswith("beacon-check consistent")


def test_most_moved():
    # fewer than half: kleeman-lab's six beacons pairs, marvelmind's four and eurobot's three
    # each alone only, at most max_beacons
    assert [bc.most_moved(n, 2) for n in (2, 3, 4, 5, 6, 16)] == [1, 1, 1, 2, 2, 2]
    assert bc.most_moved(16, 3) == 3 and bc.most_moved(6, 3) == 2 and bc.most_moved(6, 1) == 1


def test_write_fixed_moves_every_beacon():
    text = "[beacon1]\nx_m = 0.05\ny_m = 3.0\nz_m = 1.0\n\n[beacon4]\nx_m = 11.95\ny_m = 9.0\nz_m = 1.0\n"
    answer = bc.Hypothesis((bc.Move("beacon1", (0.05, 3.0, 1.0), (0.05, 3.1, 1.0)),
                            bc.Move("beacon4", (11.95, 9.0, 1.0), (11.87, 8.94, 1.2))), [0.0], [0.0])
    assert bc.write_fixed(text, answer) == ("[beacon1]\nx_m = 0.0500\ny_m = 3.1000\nz_m = 1.0\n\n"
                                            "[beacon4]\nx_m = 11.8700\ny_m = 8.9400\nz_m = 1.2000\n")


def test_cli_usage_errors(tmp_path, capsys):
    """check-beacons' counts below 1 and missing files: usage errors (64) naming the option or
    file, before any replay (no bridge needed)."""
    from beaconloc_sim import cli
    log = tmp_path / "run.log"
    log.write_text("")
    site = tmp_path / "site.ini"
    site.write_text("")
    for option in ("--iterations", "--max-beacons", "--jobs"):
        assert cli.main(["check-beacons", str(site), str(log), option, "0"]) == cli.EX_USAGE
        assert f"{option} must be >= 1" in capsys.readouterr().err
    assert cli.main(["check-beacons", str(site), str(tmp_path / "none.log")]) == cli.EX_USAGE
    assert "none.log: no such file" in capsys.readouterr().err
