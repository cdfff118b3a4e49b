"""Where the released LessMimic viewer fetches the demo export's files, and the export written there
(``lessmimic export --format lessmimic-demo --viewer-site DIR``).

Facts from the viewer (``LessMimic/lessmimic.github.io``, ``humanoid-policy-viewer/``; no licence: facts only):

* the viewer is one page, ``index.html``, in its site folder (Vite ``base: './'``: the built site
  ``static/humanoid-policy-viewer/``; in development ``public/`` is served at the page's folder);
* it reads one policy file, ``./examples/checkpoints/g1/interaction_policy.json`` (``simulation/main.js``'s
  ``defaultPolicy``), relative to the page;
* every path that JSON names is fetched by the page's script with a plain ``fetch(path)``, so it resolves against
  the **page** (the document's URL), not the JSON's folder: ``onnx.path`` and ``latent_encoder.path``
  (``interactionPolicyRunner.js``, no ``response.ok`` check: a missing file reaches onnxruntime as "No graph was
  found in the protobuf") and each ``sdf.objects`` grid (``sdfHelper.js``, checked);
* ``scene_xml`` names a file of ``./examples/scenes/`` (``files.json`` lists what is copied into MuJoCo's virtual
  file system, ``mujocoUtils.js``).

So the export writes its three files into ``DIR/examples/checkpoints/g1/`` and names the ONNX files by their path
from the page (:data:`VIEWER_URLS`). :func:`resolve` maps a URL the page fetches onto the site's files the way a
browser resolves it (``urljoin`` against ``DIR/index.html``); :func:`fetched_files` lists every file the JSON makes
the viewer fetch. The site tree after ``--viewer-site DIR``::

    DIR/index.html                                   the viewer's page (must exist)
    DIR/examples/checkpoints/g1/interaction_policy.json
    DIR/examples/checkpoints/g1/policy.onnx          "onnx": {"path": "./examples/checkpoints/g1/policy.onnx"}
    DIR/examples/checkpoints/g1/latent_encoder.onnx
    DIR/examples/scenes/g1/g1_interaction.xml        the viewer's own scene (scene_xml)
    DIR/../../lessmimic-live-demo-assets/*_sdf.json  the viewer's own grids (its config's paths, kept)
"""

from __future__ import annotations

from pathlib import Path
from urllib.parse import unquote, urljoin, urlparse

from pipeline.errors import InputError

PAGE = "index.html"
SCENES_URL = "./examples/scenes/"
#: each export file's URL from the viewer's page (the JSON's is the viewer's fixed defaultPolicy)
VIEWER_URLS = {
    "interaction_policy.json": "./examples/checkpoints/g1/interaction_policy.json",
    "latent_encoder.onnx": "./examples/checkpoints/g1/latent_encoder.onnx",
    "policy.onnx": "./examples/checkpoints/g1/policy.onnx",
}


def check_site(site: str | Path) -> Path:
    """``site`` if it is the viewer's site folder (it holds the page ``index.html``), else a one-line InputError."""
    site = Path(site)
    if not (site / PAGE).is_file():
        why = f"no {PAGE} here: pass the viewer's site folder (the one holding its page: static/humanoid-policy-viewer)"
        raise InputError(site, "viewer_site", why)
    return site


def resolve(site: str | Path, url: str) -> Path:
    """The file that ``fetch(url)`` from the page ``site/index.html`` reads when the site's folders are served as
    they lie: the URL joined to the page's, as the browser does, then read back as a path."""
    page = Path(site).resolve().as_uri() + "/" + PAGE
    return Path(unquote(urlparse(urljoin(page, url)).path))


def fetched_files(config: dict) -> dict[str, str]:
    """Every URL (from the page) that ``interaction_policy.json``'s ``config`` makes the viewer fetch, by the key
    that names it (module doc)."""
    urls = {"onnx.path": config["onnx"]["path"], "latent_encoder.path": config["latent_encoder"]["path"]}
    urls.update({f"sdf.objects.{k}": v for k, v in (config.get("sdf", {}).get("objects") or {}).items()})
    if config.get("scene_xml"):
        urls["scene_xml"] = SCENES_URL + config["scene_xml"]
    return urls


def site_report(site: str | Path, config: dict) -> list[str]:
    """One line per file the viewer at ``site`` fetches for ``config``: its key, URL, the file it resolves to and
    whether that file is there (the viewer's own grids and scene are not the export's to write)."""
    lines = []
    for key, url in fetched_files(config).items():
        path = resolve(site, url)
        lines.append(f"{key}: {url} -> {path} ({'present' if path.is_file() else 'MISSING'})")
    return lines
