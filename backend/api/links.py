"""OpenAPI links: from the POST that creates a run or a study to every operation on it.

A client (or a fuzzer such as schemathesis) that follows the links reaches each ``/api/runs/{run_id}...``
operation with the id ``POST /api/runs`` returned, instead of guessing ids that all answer 404.  The links
are derived from the paths, so an operation added under a resource is linked without editing this module.

>>> spec = {"paths": {
...     "/api/runs": {"post": {"responses": {"201": {"description": "ok"}}}},
...     "/api/runs/{run_id}": {"get": {"responses": {}}, "delete": {"responses": {}}}}}
>>> links = add_links(spec)["paths"]["/api/runs"]["post"]["responses"]["201"]["links"]
>>> sorted(links)
['DeleteRun', 'GetRun']
>>> links["GetRun"]["operationRef"], links["GetRun"]["parameters"]
('#/paths/~1api~1runs~1{run_id}/get', {'run_id': '$response.body#/id'})
"""

from __future__ import annotations

import re
from typing import Any

#: collection path -> (its noun, its item's path parameter, constant values of the item's other path parameters)
RESOURCES: dict[str, tuple[str, str, dict[str, str]]] = {
    "/api/runs": ("run", "run_id", {"fmt": "png"}),
    "/api/studies": ("study", "study_id", {"name": "summary.json"}),
}
_METHODS = ("get", "put", "post", "patch", "delete")


def _link_name(method: str, noun: str, item_path: str, resource: str) -> str:
    """``GetRun``, ``PutRunReference``, ``GetStudyFilesName``: unique per operation under a resource."""
    rest = re.sub(r"[{}.]", " ", item_path.removeprefix(resource)).replace("/", " ").split()[1:]
    words = [method, noun, *rest]
    return "".join(w[:1].upper() + w[1:] for word in words for w in word.replace("_", " ").split())


def _ref(path: str, method: str) -> str:
    return "#/paths/" + path.replace("~", "~0").replace("/", "~1") + "/" + method


def add_links(spec: dict[str, Any]) -> dict[str, Any]:
    """Add to each resource's ``POST`` success response a link to every operation under ``{id}``.

    The link passes ``$response.body#/id`` as the id, and a constant for any other path parameter (a run's
    report format, a study's file name)."""
    paths = spec.get("paths", {})
    for resource, (noun, param, constants) in RESOURCES.items():
        post = paths.get(resource, {}).get("post")
        if post is None:
            continue
        links: dict[str, Any] = {}
        for path, item in paths.items():
            if not path.startswith(f"{resource}/{{{param}}}"):
                continue
            for method in _METHODS:
                if method not in item:
                    continue
                names = re.findall(r"{(\w+)(?::\w+)?}", path)
                values = {n: ("$response.body#/id" if n == param else constants[n]) for n in names}
                links[_link_name(method, noun, path, resource)] = {"operationRef": _ref(path, method),
                                                             "parameters": values}
        for code, response in post.get("responses", {}).items():
            if code.startswith("2"):
                response["links"] = links
    return spec
