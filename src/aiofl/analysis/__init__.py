"""Analysis of plants and closed loops: closed-loop linearisation and verdicts, exact
tracking by model inversion (the least control effort of any tracking controller)."""
