"""Torch at one thread where numpy and torch alternate (codesign.threads), its pool given back after."""

import pytest
import torch

from codesign.threads import one_torch_thread


def test_one_torch_thread_holds_torch_and_gives_its_pool_back():
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        with one_torch_thread():
            assert torch.get_num_threads() == 1
        assert torch.get_num_threads() == 2
        with pytest.raises(RuntimeError), one_torch_thread():
            raise RuntimeError
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)

