"""``/v1/characters``: characters for a viewer. Motion a viewer plays that never was a result (a
clip, a live session's frames) is drawn on a character by a *binding*, computed here once per
(character, source skeleton) and applied by the viewer to every frame (:mod:`service.characters`).

* ``POST /v1/characters/binding``: how the character follows the skeleton (JSON);
* ``POST /v1/characters/model``: the character's file to draw (GLB or glTF).

A result on a character is the result download itself (``GET /v1/jobs/{id}/result?format=glb
&character=...``): the retargeting every download uses, foot planting included.
"""

from __future__ import annotations

from typing import Annotated

import anyio
from fastapi import APIRouter, Depends
from starlette.responses import Response

from schemas.characters import CharacterBinding, CharacterRequest

from ..characters import character_binding, character_model
from ..deps import ParseLimiterDep, PrincipalDep, SettingsDep, StoreDep
from ..errors import responses
from ..jsonbody import json_body, json_body_doc

router = APIRouter(prefix="/v1/characters", tags=["characters"])

CHARACTER_BODY = json_body_doc("CharacterRequest", "A character and the skeleton it is to follow.")
CharacterBody = Annotated[CharacterRequest, Depends(json_body(CharacterRequest.model_validate))]


@router.post(
    "/binding",
    response_model=CharacterBinding,
    openapi_extra=CHARACTER_BODY,
    responses=responses(401, 404, 413, 415, 422),
)
async def binding(
    body: CharacterBody,
    store: StoreDep,
    settings: SettingsDep,
    principal: PrincipalDep,
    limiter: ParseLimiterDep,
) -> CharacterBinding:
    """How a character (an uploaded glTF/GLB file or BVH clip) follows a source skeleton frame by
    frame: per character joint, the source joint whose world rotation it takes (times a constant
    offset), and where its hips go. Measured by the retargeting's own transfer on the skeleton's
    rest pose, or on ``example`` frames (then exactly what a download's retargeting does without
    its foot planting). 422 ``retarget_failed`` when the skeletons do not correspond."""
    limits = settings.bvh_limits
    return await anyio.to_thread.run_sync(character_binding, store, principal, body, limits, limiter=limiter)


@router.post(
    "/model",
    response_class=Response,
    openapi_extra=CHARACTER_BODY,
    responses=responses(
        401,
        404,
        413,
        415,
        422,
        extra={200: {"description": "the character's file", "content": {"model/gltf-binary": {}}}},
    ),
)
async def model(
    body: CharacterBody,
    store: StoreDep,
    settings: SettingsDep,
    principal: PrincipalDep,
    limiter: ParseLimiterDep,
) -> Response:
    """The character's file for a viewer to draw: an uploaded glTF/GLB file as it was uploaded
    (422 ``not_a_character`` when it holds no skinned skeleton)."""
    data, media = await anyio.to_thread.run_sync(
        character_model, store, principal, body, settings.bvh_limits, limiter=limiter
    )
    return Response(data, media_type=media)
