"""Pelco-P and Pelco-D: a pure frame codec and the serial link that carries it."""
