"""`sdrpeer demo`: the paper's demonstration (section III) on one machine, measured and plotted.

Modules: `collect` (pure: agents' answers -> timeline lines), `timeline` (the recorder thread
and `load_timeline`), `query` (the `Timeline` helpers for the figures of merit), `figures`
(Figs. 4-6 as PNG; matplotlib is imported there only, inside the function).
"""
