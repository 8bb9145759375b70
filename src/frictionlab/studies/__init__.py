"""Studies: runs of the model over many configurations -- parameter sweeps
(:mod:`.sweep`), identification (:mod:`.identification`), compensator tuning
(:mod:`.compensation`), the thesis's figures and tables (:mod:`.reproduce`)
and the predicted limit cycle (:mod:`.predict`).

They import the configuration and the model, never the command line, the
console or the real-time loop (docs/architecture.md).
"""
