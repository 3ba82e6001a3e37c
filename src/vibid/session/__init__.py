"""The session file (shared/spec/session-format.md): the data layer under acquisition and replay.

It lives beside, not inside, acquisition/: the writer serves the live campaign, the reader
serves signal/ and the replay, and neither may depend on acquisition/.
"""

from vibid.session.format import FORMAT, FORMAT_VERSION, STEP_STATUSES
from vibid.session.reader import Session, SessionFileError, Step, load_setup, read_session
from vibid.session.validate import Problem, file_problems
from vibid.session.writer import SessionWriter, utc_now

__all__ = [
    "FORMAT",
    "FORMAT_VERSION",
    "STEP_STATUSES",
    "Session",
    "SessionFileError",
    "Step",
    "load_setup",
    "read_session",
    "Problem",
    "file_problems",
    "SessionWriter",
    "utc_now",
]
