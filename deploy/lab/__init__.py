"""The lab: experiments run in one process per job (no Zenoh), their reports, and a multi-host lab.

:mod:`~swarmloc.deploy.lab.experiment` is the experiment engine (``swarmloc experiment``: a spec's
grid of settings, seeded replications in a pool of processes, resumable results); the report
engine is :mod:`~swarmloc.deploy.lab.report` (``swarmloc report``: its family-free parts and the
registry of each family's template); :mod:`~swarmloc.deploy.lab.netns`
builds a multi-host lab in Linux network namespaces; :mod:`~swarmloc.deploy.lab.executors` runs an
experiment's jobs on the local process pool or a Dask cluster. Each robot family's runner, experiment hooks
(``experiment.py``, named by the family's entry in ``swarmloc.families.FAMILIES``) and report template (``report.py``) sit
in its own folder (``epuck/``, ``laser/``, ``vision/``, ``replay/``).
"""
