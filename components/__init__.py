"""Ready-made components (the paper's demonstration components arrive with the components issue)."""
