# filled in by the Cortex-M4 port
