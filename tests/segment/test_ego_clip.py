"""One ego body per camera: the vote, the constant-pixel witness, and masks given exactly that body."""

import numpy as np
import pytest

from cama_pipeline.segment.ego_clip import EgoClipConfig, EgoVote, agreed_constant, camera_body, with_body
from cama_pipeline.semantics import Semantic

EGO, ROAD, SKY = int(Semantic.EGO), int(Semantic.ROAD), int(Semantic.SKY)


def road_with_ego(rows: slice, cols: slice) -> np.ndarray:
    mask = np.full((8, 10), ROAD, np.uint8)
    mask[rows, cols] = EGO
    return mask


def test_the_vote_keeps_pixels_labelled_ego_in_enough_masks() -> None:
    vote = EgoVote()
    vote.add(road_with_ego(slice(5, 8), slice(2, 8)))
    vote.add(road_with_ego(slice(5, 8), slice(2, 8)))
    vote.add(road_with_ego(slice(6, 8), slice(0, 3)))  # one frame's mistake
    body = vote.voted(0.5)
    assert body.sum() == 18 and body[5:8, 2:8].all()
    assert vote.voted(1.0).sum() == 2 and vote.voted(0.3).sum() == 18 + 4
    with pytest.raises(ValueError, match="shape"):
        vote.add(np.zeros((4, 4), np.uint8))
    with pytest.raises(ValueError, match="no mask"):
        EgoVote().voted(0.5)


def test_the_constant_witness_fills_what_the_network_misses_in_every_frame() -> None:
    vote = EgoVote()
    for _ in range(4):
        vote.add(road_with_ego(slice(6, 8), slice(2, 8)))  # the network misses the body's top row everywhere
    constant = np.zeros((8, 10), bool)
    constant[5:8, 2:8] = True
    stray = np.zeros((8, 10), bool)
    stray[0, 0] = True  # one clip's wall: not agreed by half of the clips
    assert agreed_constant([constant, constant | stray, constant]) is not None
    body = camera_body(vote, [constant, constant | stray, constant], 0.5)
    assert body.sum() == 18 and not body[0, 0]
    assert agreed_constant([]) is None
    assert camera_body(vote, [], 0.5).sum() == 12
    with pytest.raises(ValueError, match="estimate"):
        camera_body(vote, [np.zeros((3, 3), bool)], 0.5)


def test_masks_get_exactly_the_body_and_stray_ego_takes_the_nearest_label() -> None:
    mask = np.full((8, 10), ROAD, np.uint8)
    mask[:3] = SKY
    mask[0, 8:] = EGO  # stray ego in the sky
    mask[7, 4:6] = EGO  # part of the body
    body = np.zeros((8, 10), bool)
    body[6:8, 3:7] = True
    out = with_body(mask, body)
    assert ((out == EGO) == body).all()
    assert (out[0, 8:] == SKY).all()  # the nearest label that is neither ego nor body
    assert (out[~body & (mask != EGO)] == mask[~body & (mask != EGO)]).all()
    assert (with_body(np.full((4, 4), EGO, np.uint8), np.zeros((4, 4), bool)) == 0).all()
    with pytest.raises(ValueError, match="differ"):
        with_body(mask, np.zeros((3, 3), bool))


def test_config_is_checked() -> None:
    with pytest.raises(ValueError, match="vote_share"):
        EgoClipConfig(vote_share=0.0)
    assert EgoClipConfig().to_json()["vote_share"] == 0.5
