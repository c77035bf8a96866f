"""The deploy layer: the ``swarmloc`` command (:mod:`.cli`), what starts a run (:mod:`.launch`,
:mod:`.run`, :mod:`.scenario`, :mod:`.warm`), observers (``observe/``) and the in-process lab
(``lab/``: experiment and report engines, one folder per robot family)."""
