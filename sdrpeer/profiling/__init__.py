"""`sdrpeer profile`: measuring a component in advance in a real host (measure.py) with
synthetic or recorded inputs (inputs.py)."""
