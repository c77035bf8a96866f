"""The agent layer: the agent-node shell (:mod:`.node`), the :class:`~.brains.AgentBrain`
contract with its family registry (:mod:`.brains`), and one folder per robot family
(``epuck/``, ``laser/``, ``vision/``, ``replay/``) holding its pure brains and its adapter."""
