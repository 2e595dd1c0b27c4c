"""Dynamic module allocation: a pure core from (system, cluster view) to a plan."""
