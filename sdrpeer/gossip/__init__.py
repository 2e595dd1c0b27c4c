"""Gossip: SWIM membership with Lifeguard refinements, dissemination, and the UDP shell."""
