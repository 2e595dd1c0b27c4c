"""The network-namespace lab: each robot in its own namespace on a private bridge (root)."""
