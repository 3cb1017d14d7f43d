"""Tests of the hipref package (a package so worker processes can import tests._sweep_cells)."""
