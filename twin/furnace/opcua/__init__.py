"""A furnace over OPC UA: the twin's plant adapter (client side).

``nodes`` (the address space the twin expects, and mapping files), ``endpoints`` (which endpoints a server
may connect to), ``options`` (``FURNACE_TWIN_OPCUA_*``), ``security`` (certificates, user names),
``browse`` (finding the nodes), ``samples`` (readings grouped into samples by their source timestamps),
``link`` (the asyncio client: subscribe, write, reconnect) and ``furnace`` (``OpcUaFurnace``, the
:class:`twin.furnace.interface.Furnace` the loop runs).  The package itself imports none of them, so
validating an endpoint does not load asyncua.
"""
