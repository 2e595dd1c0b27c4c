"""The network lab: each robot in its own namespace on a private bridge (root), and a packet
capture on an interface (`capture`: what an eavesdropper reads and could replay)."""
