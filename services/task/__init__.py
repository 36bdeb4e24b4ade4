"""Task orchestration: the pick cycle state machine, recovery, status and pick events."""
