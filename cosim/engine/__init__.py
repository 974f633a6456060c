"""The engine: the scenario, the system plan, the algorithms and the execution that runs them, the offload
worker, the watchdog and the supervisor, the pre-flight. Imports only the FMI layer and the error root."""
