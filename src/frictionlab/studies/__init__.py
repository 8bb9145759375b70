"""Studies: runs of the model over many configurations -- parameter sweeps
(:mod:`.sweep`) and their compiled batch evaluator (:mod:`.batch`),
identification (:mod:`.identification`), compensator tuning
(:mod:`.compensation`), the thesis's figures and tables (:mod:`.reproduce`),
the predicted limit cycle (:mod:`.predict`) and swing-up runs
(:mod:`.swingup_sim`).

They import the configuration, the model and the real-time loop (experiments
on a rig, :mod:`.identification.onrig`), never the command line or the
console (docs/architecture.md).
"""
