import os

import numpy as np
import pytest

# A rotating seed (scikit-learn's habit): set TRANSYNC_SEED to reproduce a failure.
_SEED = int(os.environ.get("TRANSYNC_SEED", "0"))


@pytest.fixture
def rng():
    return np.random.default_rng(_SEED)
