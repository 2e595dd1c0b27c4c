"""What a benchmark ends with: its table printed, its figures written as JSON when asked."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any


def finish(figures: dict[str, Any], table: str, json_path: Path | None) -> int:
    """Print `table`; write `figures` to `json_path` (its directory made) when given; 0."""
    print(table)
    if json_path is not None:
        json_path.parent.mkdir(parents=True, exist_ok=True)
        json_path.write_text(json.dumps(figures, indent=2) + "\n")
        print(f"wrote {json_path}")
    return 0
