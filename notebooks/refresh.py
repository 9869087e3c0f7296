"""Run notebooks top to bottom in a fresh kernel and save them with their new outputs.

    python notebooks/refresh.py                      # every notebook in this folder
    python notebooks/refresh.py notebooks/02_*.ipynb # some of them

Each notebook runs in its own fresh ``python3`` kernel, started in the notebook's folder with
the same environment the tests give it (the shared numba cache of ``conftest.py``), and the
outputs are stored exactly as ``pytest --nbval`` collects them, so a refreshed notebook passes
the strict comparison. A slider cell (one that displays a widget) is stored without outputs:
widget model ids change every run, nbval does not compare such cells, and the figure it draws
for its default values is the one shown by a plain cell before it. A cell that raises stops
the run and leaves that notebook unchanged.

Needs only the test extra (``jupyter_client``, ``ipykernel``, ``nbformat``).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path
from queue import Empty

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
WIDGET_MIME = "application/vnd.jupyter.widget-view+json"
CELL_TIMEOUT = 600  # seconds


def _kernel_env() -> None:
    # the settings conftest.py gives the kernels nbval starts
    os.environ.setdefault("NUMBA_CACHE_DIR", str(ROOT / ".numba_cache"))
    os.environ.setdefault("NUMBA_THREADING_LAYER", "threadsafe")


def _coalesce(outputs: list) -> list:
    """Join consecutive stream outputs of the same name, as nbval compares them."""
    out: list = []
    for o in outputs:
        if (o.output_type == "stream" and out and out[-1].output_type == "stream"
                and out[-1].name == o.name):
            out[-1].text += o.text
        else:
            out.append(o)
    return out


def run_notebook(path: Path) -> float:
    """Execute ``path`` in place; return the seconds it took."""
    import nbformat
    from jupyter_client.manager import start_new_kernel

    nb = nbformat.read(path, as_version=4)
    km, kc = start_new_kernel(kernel_name="python3", cwd=str(path.parent))
    t0 = time.perf_counter()
    try:
        count = 0
        for index, cell in enumerate(nb.cells):
            if cell.cell_type != "code":
                continue
            if not cell.source.strip():
                cell.outputs, cell.execution_count = [], None
                continue
            msg_id = kc.execute(cell.source, allow_stdin=False)
            outputs = []
            widget = False
            while True:
                try:
                    msg = kc.get_iopub_msg(timeout=CELL_TIMEOUT)
                except Empty:
                    raise RuntimeError(f"{path.name}: cell {index} gave no output for "
                                       f"{CELL_TIMEOUT} s") from None
                if msg["parent_header"].get("msg_id") != msg_id:
                    continue
                kind, content = msg["msg_type"], msg["content"]
                if kind == "status" and content["execution_state"] == "idle":
                    break
                if kind == "error":
                    tb = "\n".join(content["traceback"])
                    raise RuntimeError(f"{path.name}: cell {index} raised\n{tb}")
                if kind == "execute_input":
                    count = content["execution_count"]
                if kind in ("stream", "display_data", "execute_result"):
                    if kind != "stream" and WIDGET_MIME in content.get("data", {}):
                        widget = True
                        continue
                    outputs.append(nbformat.v4.output_from_msg(msg))
            cell.outputs = [] if widget else _coalesce(outputs)
            cell.execution_count = count
            for o in cell.outputs:
                if o.output_type == "execute_result":
                    o.execution_count = count
    finally:
        kc.stop_channels()
        km.shutdown_kernel(now=True)
    nb.metadata["kernelspec"] = {"name": "python3", "display_name": "Python 3 (ipykernel)",
                                 "language": "python"}
    nb.metadata["language_info"] = {"name": "python", "pygments_lexer": "ipython3"}
    nbformat.validate(nb)
    tmp = path.with_name(path.name + ".tmp")
    nbformat.write(nb, tmp)
    os.replace(tmp, path)
    return time.perf_counter() - t0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="Run notebooks in a fresh kernel and save their outputs.")
    parser.add_argument("notebooks", nargs="*", type=Path,
                        help="notebooks to refresh (default: every *.ipynb beside this script)")
    args = parser.parse_args(argv)
    paths = args.notebooks or sorted(HERE.glob("*.ipynb"))
    _kernel_env()
    total = 0.0
    for p in paths:
        try:
            seconds = run_notebook(p.resolve())
        except RuntimeError as exc:
            print(exc, file=sys.stderr)
            return 1
        total += seconds
        print(f"{p}: {seconds:.1f} s")
    print(f"{len(paths)} notebook(s) in {total:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
