"""What every bad-input module asserts of a refusal (importable: pytest puts tests/ on sys.path)."""

import pytest


def raises(build, field: str, fix: str) -> str:
    """``build()`` raises a ValueError whose message starts with ``field`` and carries ``fix``; the message."""
    with pytest.raises(ValueError) as error:
        build()
    message = str(error.value)
    assert message.startswith(f"{field}: "), message
    assert fix in message, message
    return message
