import os

import pytest

os.environ.setdefault("MPLBACKEND", "Agg")


@pytest.fixture(scope="session")
def fast_design():
    from frictionlab.design import design

    return design("fast")
