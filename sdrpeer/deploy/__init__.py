"""Deployment: election shell, plan store and sync, plan -> instance specs, the allocator role."""
