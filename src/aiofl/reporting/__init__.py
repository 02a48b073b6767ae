"""Reproduction of the paper: cases, tables, figures and the HTML report."""
