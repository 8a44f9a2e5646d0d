"""tools.log.versions: a log of another build's schema versions is said so, not read as an empty run."""

from __future__ import annotations

import pytest

from shared.protocol import ProtocolError
from shared.runtime import UserError
from tools.log.versions import check_readable


def _refused(reason: str) -> ProtocolError:
    return ProtocolError(f"refused ({reason})", reason=reason)


def test_nothing_decoded_and_every_message_of_another_version_is_an_error_naming_them() -> None:
    with pytest.raises(UserError, match=r"^its 2 Plan message\(s\) are of a schema version this build does not read"):
        check_readable(0, [_refused("version"), _refused("version")], "Plan message(s)")


@pytest.mark.parametrize(("decoded", "reasons"), [(1, ["version"]), (0, ["version", "malformed"]), (0, [])])
def test_a_log_with_something_readable_or_other_faults_is_read_as_it_is(decoded: int, reasons: list[str]) -> None:
    check_readable(decoded, [_refused(r) for r in reasons])
