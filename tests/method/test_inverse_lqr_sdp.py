

def test_a_solver_message_is_never_cut_mid_sentence():
    """A long solver error joined into the attempts' list: cut at a clause it finishes, marked with "…" (the previous
    main cut at 200 characters and printed "… the problem is ; CLARABEL stage 2 …")."""
    from workbench.method.inverse_lqr_sdp import _brief

    long = ("SolverError: Solver CLARABEL failed because the problem is numerically difficult and no solution was "
            "found within the iteration limit the caller gave it; the problem is ill-conditioned; rescale the data")
    text = _brief(long)
    assert len(text) <= 202 and text.endswith(" …") and not text.endswith("is …")
    assert text.startswith("SolverError: Solver CLARABEL failed") and "gave it" in text
    assert _brief("short message") == "short message"
