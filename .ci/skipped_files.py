"""The test files that skipped for want of something installable, from a pytest log (its ``-ra`` summary).

Reads the log on stdin; prints each test file, once, in order, whose ``SKIPPED [N] FILE:LINE: REASON`` names an
install (an extra, a package or a program: ``pip install``, ``apt-get install``, ``not installed``, ``extra``, a
failed import). .ci/run re-runs those files after it has installed the extras, and only those: a second run of the
whole suite would double CI's time. Skips for other reasons (no CUDA GPU, no cache folder) are not re-run.
"""

import re
import sys

WANT = re.compile(r"pip install|apt-get install|not installed|\bextra\b|could not import|no module named", re.I)
LINE = re.compile(r"^SKIPPED \[\d+\] (\S+?\.py)(?::\d+)?: (.*)$")


def skipped_files(log: str) -> list[str]:
    """The files (in order of first mention) of the skip lines of ``log`` whose reason names an install."""
    found = []
    for line in log.splitlines():
        m = LINE.match(line.strip())
        if m and WANT.search(m.group(2)) and m.group(1) not in found:
            found.append(m.group(1))
    return found


if __name__ == "__main__":
    print("\n".join(skipped_files(sys.stdin.read())))
