"""The world package's public names exist."""

import world


def test_public_names_exist() -> None:
    for name in world.__all__:
        assert hasattr(world, name), name
