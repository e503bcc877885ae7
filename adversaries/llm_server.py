"""Child-process entry point: serve one GGUF model on 127.0.0.1 with xllamacpp's llama.cpp server.

``python llm_server.py MODEL PORT THREADS CONTEXT`` (run as a file, not imported). The server lives in this
process until its stdin closes: the parent (`llm_backends.local_server_url`) holds the pipe, so
the server stops when the parent stops it *or* dies, and no orphan keeps a port or a core.
"""

from __future__ import annotations

import sys


def main(argv: list[str]) -> int:
    """Start the server and block until stdin reaches end of file."""
    import xllamacpp

    model, port, threads, context = argv[0], int(argv[1]), int(argv[2]), int(argv[3])
    params = xllamacpp.CommonParams()
    params.model.path = model
    params.hostnames = ["127.0.0.1"]
    params.port = port
    params.cpuparams.n_threads = threads
    params.cpuparams_batch.n_threads = threads
    params.n_ctx = context
    params.n_parallel = 1
    params.verbosity = 0
    server = xllamacpp.Server(params)
    sys.stdin.read()  # returns at EOF: the parent closed the pipe or died
    del server
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
