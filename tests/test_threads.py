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



@pytest.mark.parametrize("torch_first", [False, True])
def test_a_workers_torch_runs_one_thread_whether_loaded_before_or_after_the_limits(torch_first):
    """limit_threads does not import torch (most workers never train), yet any torch in a worker has one thread."""
    import json
    import subprocess
    import sys

    code = ("import json, os, sys\n"
            "for var in ('OMP_NUM_THREADS', 'MKL_NUM_THREADS'): os.environ.pop(var, None)\n"
            + ("import torch\ntorch.set_num_threads(2)\n" if torch_first else "")
            + "from compare.run.execution import limit_threads\n"
            "limit_threads()\n"
            "loaded = 'torch' in sys.modules\n"
            "import torch\n"
            "print(json.dumps([loaded, torch.get_num_threads()]))\n")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    loaded, threads = json.loads(done.stdout.strip().splitlines()[-1])
    assert loaded == torch_first and threads == 1
