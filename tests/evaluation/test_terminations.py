"""Termination counts of an evaluation, computed by hand on a 4-step x 5-env rollout; stored, read back, drawn."""

from __future__ import annotations

import numpy as np
import pytest

from morfic_cli.evaluation.figures import verdict_line
from morfic_cli.evaluation.terminations import (
    TERMINATION_COLUMNS,
    TERMINATIONS_CSV,
    failure_text,
    parse_terminations,
    read_terminations,
    termination_counts,
    termination_lines,
    termination_names,
)
from morfic_cli.recording.tables import rows_to_csv

NAMES = ("illegal_contact", "excessive_tilt", "base_too_low", "nonfinite")


def _rollout() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """done, time_out (T, N) and the term masks (T, N, K) of 4 steps x 5 envs:

    - env 0 falls at step 1, tilted and too low at once (two terms on its fatal step);
    - env 1 times out at step 2, then its second episode ends by illegal contact at step 3 (not counted);
    - env 2's physics goes non-finite at step 2;
    - env 3 runs to the end (its base is too low at step 0 without ending: only ends count);
    - env 4 ends by illegal contact at step 0, and again at step 3 (its second episode: counted once).
    """
    t, n = 4, 5
    done, time_out = np.zeros((t, n), bool), np.zeros((t, n), bool)
    masks = np.zeros((t, n, len(NAMES)), bool)
    k = {name: i for i, name in enumerate(NAMES)}
    done[1, 0] = masks[1, 0, k["excessive_tilt"]] = masks[1, 0, k["base_too_low"]] = True
    done[2, 1] = time_out[2, 1] = True
    done[3, 1] = masks[3, 1, k["illegal_contact"]] = True
    done[2, 2] = masks[2, 2, k["nonfinite"]] = True
    masks[0, 3, k["base_too_low"]] = True
    done[0, 4] = masks[0, 4, k["illegal_contact"]] = True
    done[3, 4] = masks[3, 4, k["illegal_contact"]] = True
    return done, time_out, masks


def test_each_failed_envs_fatal_step_counts_every_term_it_tripped():
    done, time_out, masks = _rollout()
    counts = termination_counts(done, time_out, masks, NAMES)
    assert counts == {"illegal_contact": 1, "excessive_tilt": 1, "base_too_low": 1, "nonfinite": 1}
    assert list(counts) == list(NAMES)
    # 3 envs failed (0, 2, 4); env 0 tripped two terms, so the counts sum to 4
    assert sum(counts.values()) == 4


def test_no_end_or_time_outs_only_count_nothing_and_shapes_must_match():
    done, time_out, masks = _rollout()
    assert termination_counts(np.zeros_like(done), time_out, masks, NAMES) == dict.fromkeys(NAMES, 0)
    assert termination_counts(done, done, masks, NAMES) == dict.fromkeys(NAMES, 0)  # every first end a time-out
    with pytest.raises(ValueError, match=r"\(T, N, K\)"):
        termination_counts(done, time_out, masks[..., :3], NAMES)


def test_the_recorded_terms_are_the_envs_termination_terms_then_nonfinite():
    assert termination_names() == NAMES


def test_counts_go_to_the_csv_and_back_and_into_the_verdict_line():
    counts = {"illegal_contact": 3, "excessive_tilt": 0, "base_too_low": 1, "nonfinite": 0}
    rows = [{"robot": "b1", "mode": "full", "command_vx": 2.0, "terminations": counts, "survival": 0.5}]
    lines = termination_lines(rows)
    assert [(r["term"], r["envs"]) for r in lines] == list(counts.items())
    data = rows_to_csv(lines, TERMINATION_COLUMNS)
    assert data.decode().splitlines()[:2] == ["robot,mode,command_vx,term,envs", "b1,full,2.0,illegal_contact,3"]
    assert parse_terminations(data) == lines
    assert failure_text(counts) == "illegal_contact 3, base_too_low 1"
    assert failure_text(None) == failure_text(dict.fromkeys(NAMES, 0)) == ""
    outcomes = np.array(["ok", "falls", "falls", "falls"])
    assert verdict_line(outcomes, "falls", counts) == (
        "verdict: falls \u2013 valid 1/4 (falls 3)\nended by illegal_contact 3, base_too_low 1",
        False,
    )
    assert verdict_line(outcomes, "falls", dict.fromkeys(NAMES, 0)) == verdict_line(outcomes, "falls")


def test_a_stored_evals_counts_survive_a_results_only_bundle_and_older_evals_have_none(tmp_path):
    from morfic_cli.store import Store

    src = Store(tmp_path / "src")
    ckpt = src.put_manifest("checkpoint", config={"variant": "film"}, files={"model.pt": b"w", "curve.csv": b"it\n1"})
    src.set_ref("runs/x", ckpt)
    src.set_ref("runs/old", src.put_manifest("checkpoint", config={"variant": "ppo"}, files={"model.pt": b"v"}))
    counts = {"illegal_contact": 2, "excessive_tilt": 1, "base_too_low": 0, "nonfinite": 0}
    lines = termination_lines([{"robot": "go1", "mode": "descriptor", "command_vx": 2.5, "terminations": counts}])
    table = b"robot,mode,command_vx,survival\ngo1,descriptor,2.5,0.75\n"
    new = src.put_manifest(
        "eval",
        inputs={"checkpoint": ckpt},
        files={"eval.csv": table, TERMINATIONS_CSV: rows_to_csv(lines, TERMINATION_COLUMNS)},
        meta={"run": "x"},
    )
    src.set_ref("evals/x", new)
    old = src.put_manifest(
        "eval", inputs={"checkpoint": src.resolve("runs/old")}, files={"eval.csv": table}, meta={"run": "old"}
    )
    src.set_ref("evals/old", old)
    assert read_terminations(src, "evals/x") == lines
    assert read_terminations(src, "evals/old") == []  # predates the counts: not recorded
    dst = Store(tmp_path / "dst")
    dst.import_tar(src.export_tar(["runs/x", "runs/old"], tmp_path / "x.tar", results_only=True).path)
    assert read_terminations(dst, "evals/x") == lines
    assert read_terminations(dst, "evals/old") == []
