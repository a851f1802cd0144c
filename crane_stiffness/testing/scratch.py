"""A benchmark's scratch directory at its end: kept for a look (``--keep``, the path said) or removed."""
from __future__ import annotations

import shutil
from pathlib import Path


def keep_or_remove(scratch: Path, keep: bool) -> None:
    """Keep ``scratch`` and print where it is (``keep``), else remove it with everything in it."""
    if keep:
        print(f'kept {scratch}')
    else:
        shutil.rmtree(scratch, ignore_errors=True)
