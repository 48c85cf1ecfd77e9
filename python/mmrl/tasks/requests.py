"""The vector envs' request methods (docs/styles.md): a mixin of ``TargetVectorEnv`` over the
C++ env's per-env request (cpp/include/mmrl/tags.hpp, vecenv.hpp)."""
from __future__ import annotations

import numpy as np


class RequestMethods:
    """Pin, read and describe each env's request over the database's tags. Needs ``_core`` (the
    C++ env), ``db`` and ``observe(i)`` of the env it is mixed into."""

    def set_request(self, i: int, request: str) -> np.ndarray:
        """Pin env i's request over the database's tags (``"style=elderly & gait=walk"``; ``""``
        unpins): from its next decision on, its matches and episode starts keep to the clips
        carrying it, and its observation carries the request's code. Returns its new observation.

        Raises:
            ValueError: an unknown group or tag, or a request that selects no valid frame (the
                message lists the tags available).
        """
        if not isinstance(request, str):
            raise TypeError(f"request: expected a string such as 'style=elderly', got {type(request).__name__}")
        self._core.set_request(int(i), request)
        return self.observe(i)

    def request(self, i: int) -> str:
        """Env i's request now, canonical ('' = every clip)."""
        return self._core.request(int(i))

    @property
    def request_dim(self) -> int:
        """Floats of the request code at the end of each observation (0 without request_groups)."""
        return int(self._core.request_dim)

    @property
    def request_tags(self) -> list:
        """The tags of the request code, in its order (per conditioned group, its tags)."""
        groups = list(self._core.request_groups)
        return [t for g in groups for t in self.db.tag_names if t.partition("=")[0] == g]

    def request_mix(self) -> list:
        """The requests an episode draws: (text, probability) pairs ([] without request_groups)."""
        return list(self._core.request_mix())

