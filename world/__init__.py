"""The world layer: the world-server shell (:mod:`.server`), the :class:`~.service.ServedWorld`
contract with its family registry (:mod:`.service`), and one folder per robot family
(``epuck/``, ``laser/``, ``vision/``, ``replay/``) holding its pure world model and its adapter."""
