"""The seam between the campaign manager and the models it runs: the interface a model
declares (:mod:`.interface`) and the registry that finds models by name (:mod:`.registry`).
The shipped models are plugins registered like a user's."""
