"""The paper 004 report notes: the words follow the measured rows, the numbers are theirs."""

from __future__ import annotations

from typing import Any

from navreplay.pipeline.estimation.ins.fuzzy import FuzzyParams
from navreplay.pipeline.experiments.fwekf_notes import convergence_note, faults_note

FZ = FuzzyParams()


def _fault(scen: str, name: str, rms: float, win: float | None = None) -> dict[str, Any]:
    return {
        "scenario": scen, "filter": name, "pos_h_rms_m": rms, "pos_h_max_m": 2 * rms,
        "pos_h_rms_in_window_m": win, "pos_h_max_in_window_m": win, "nis_pos_mean": 1.0,
        "nis_pos_consistent": True, "gate_rejections": 0, "gate_resets": 0,
        "alpha_median": 1.0, "alpha_p95": 1.04,
    }  # fmt: skip


def test_faults_note_says_helps_hurts_or_no_difference_against_alpha_one() -> None:
    rows = [
        _fault("nominal", "lc_ekf", 1.0), _fault("nominal", "lc_ekf_white", 1.0),
        _fault("nominal", "fwekf", 1.1),
        _fault("F8", "lc_ekf", 1.0), _fault("F8", "lc_ekf_white", 6.0),
        _fault("F8", "fwekf", 6.01),
        _fault("outages", "lc_ekf", 2.0, 3.0), _fault("outages", "lc_ekf_white", 2.0, 3.0),
        _fault("outages", "fwekf", 1.5, 2.5),
    ]  # fmt: skip
    note = faults_note(rows, FZ)
    nominal, f8, outages = (ln for ln in note.splitlines() if ln.startswith("- "))
    assert "Against alpha = 1: FWEKF hurts (+10.0 %)" in nominal
    assert "Against alpha = 1: no material difference (+0.2 %)" in f8
    assert "against lc_ekf: FWEKF hurts (+501.0 %)" in f8
    assert "Against alpha = 1: FWEKF helps (-25.0 %)" in outages
    assert "in the windows 2.50 m against 3.00 m (alpha = 1)" in outages
    assert "gate rejections / resets 0 / 0 (alpha = 1: 0 / 0, lc_ekf: 0 / 0)" in outages
    assert "Fig. 3" in note  # our reading of the memberships
    assert "[0.0, 2.0, 5.0]" in note


def _conv(case: str, tuning: str, name: str, settle: float | None) -> dict[str, Any]:
    return {
        "case": case, "tuning": tuning, "filter": name, "pos_err_at_10s_m": 0.004,
        "vel_err_at_10s_mps": 0.001, "pos_err_at_20s_m": 0.6,
        "pos_below_0.5m_from_s": settle, "vel_below_0.02mps_from_s": 8.0,
        "pos_rms_after_20s_m": 0.5, "vel_rms_after_20s_mps": 0.02,
        "alpha_median": 1.0, "alpha_max": 1.02,
    }  # fmt: skip


def test_convergence_note_puts_the_papers_figures_beside_ours() -> None:
    rows = [
        _conv("noisy", "declared", "lc_ekf", 30.0), _conv("noisy", "declared", "fwekf", 25.0),
        _conv("noise_free", "declared", "lc_ekf", 0.1),
        _conv("noise_free", "declared", "fwekf", 0.1),
        _conv("noisy", "paper_r", "lc_ekf", None), _conv("noisy", "paper_r", "fwekf", None),
    ]  # fmt: skip
    note = convergence_note(rows, FZ)
    assert "EKF with noise below 0.5 m within 20 s. Ours (declared accuracies): 0.6 m" in note
    assert "staying below 0.5 m from 30.0 s" in note
    assert "Ours, noisy, declared: settling below 0.5 m, FWEKF 5.0 s earlier" in note
    assert "Ours, noise_free, declared: settling below 0.5 m, the same time" in note
    assert "Ours, noisy, paper_r: settling below 0.5 m, neither stays below 0.5 m" in note
    assert "0.0040 m and 0.0010 m/s at 10 s" in note
    assert "alpha of up to 1.020 shortens the filter's memory to about 12 fixes" in note
