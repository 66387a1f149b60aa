"""Two namespaces a restarted furnace server may register before its own (furnace.py --spare-namespaces): its
own then has another index, which a client must find again by its URI (``nsu=``)."""

import o6

o6.ns.namespace("spare1", uri="urn:lab:spare:1")
o6.ns.namespace("spare2", uri="urn:lab:spare:2")
