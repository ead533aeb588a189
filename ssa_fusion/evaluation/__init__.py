"""Scoring any run or bag: the evaluation arms, Monte Carlo, pass reports, NEES and coverage.

It imports only the core, so a live bag and an offline study are scored by the same code.
"""
