"""The debug dashboard: a bounded metric history, live server-sent events, the page."""
