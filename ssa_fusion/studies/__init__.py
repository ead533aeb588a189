"""The experiments: the AAS 25-577 reproduction, the real-sky, gap and catalog studies, plots.

Studies put the simulated world (`ssa_fusion.sim`), the estimator (`ssa_fusion.core`) and
the scoring (`ssa_fusion.evaluation`) together; nothing below them imports a study.
"""
