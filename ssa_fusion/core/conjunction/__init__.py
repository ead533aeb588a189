"""Close approaches: screening pairs, times of closest approach, collision probability.

Imports the rooms below it (`base` to `catalog`).
"""
