"""The performance figures of ``furnace-twin bench`` (product.md): numerics (``bench``), the stream
(``stream``, against a server in its own process: ``stream_server``) and hardware in the loop (``hil``).

Outside ``twin`` and ``backend``: a benchmark measures both, so it sits above them."""
