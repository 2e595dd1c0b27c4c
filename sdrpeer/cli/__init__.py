"""The `sdrpeer` command line: every command lives here (main.py builds the parser); no other
package imports it."""
