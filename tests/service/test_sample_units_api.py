"""The bundled salsa samples keep the unit their catalogue declares (cmu-scaled: 1.46 m dancers)
when the browser uploads them as ``GET /samples`` serves them, and when a spec names them."""

from __future__ import annotations

from fastapi.testclient import TestClient

from motion.samples import SAMPLES, sample_path


def test_the_browsers_upload_of_a_salsa_sample_is_in_its_declared_unit(client: TestClient) -> None:
    file = SAMPLES["salsa-follower-05"]
    served = client.get(f"/samples/{file}")
    assert served.status_code == 200 and served.content == sample_path("salsa-follower-05").read_bytes()
    r = client.post("/v1/clips", files={"file": (file, served.content)})
    assert r.status_code in (200, 201), r.text
    clip = r.json()
    assert clip["units"] == "cmu-scaled" and 1.4 <= clip["height_m"] <= 1.5
    # the same bytes under another name are a plain file, but a clip is stored once: the id answers
    again = client.post("/v1/clips", params={"name": "mine.bvh.gz"}, content=served.content)
    assert again.status_code == 200 and again.json()["units"] == "cmu-scaled"
    # a walk declares nothing: guessed (cm)
    walk = client.post("/v1/clips", files={"file": (SAMPLES["walk"], sample_path("walk").read_bytes())})
    assert walk.json()["units"] == "cm"
