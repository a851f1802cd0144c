"""The /stiffness6/* matrix layout (crane_stiffness.contract.stiffness6_layout), both directions: a K with its interval
encoded and decoded is the same K, bit for bit; the MultiArrayLayout a ROS tool reads names the dimensions
quantity, row, column with the std_msgs strides (108, 36, 6), and entry (q, i, j) sits where those strides put it;
the module imports no ROS."""
from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from helpers import run_without_ros
from crane_stiffness.contract import stiffness6_layout as layout


def _matrices(seed: int = 6) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A K-like (6, 6) [N/m .. N·m/rad] with a distinct value in every entry, and an interval around it."""
    rng = np.random.default_rng(seed)
    k = rng.normal(0.0, 1e4, (6, 6)) + np.diag([7e4, 7e4, 2e6, 1.8e4, 1.8e4, 1.9e3])
    return k, k - rng.uniform(1.0, 50.0, (6, 6)), k + rng.uniform(1.0, 50.0, (6, 6))


def test_the_labels_sizes_and_strides_are_the_std_msgs_convention() -> None:
    assert layout.DIMS == (('quantity', 3, 108), ('row', 6, 36), ('column', 6, 6))
    assert layout.QUANTITIES == ('value', 'ci95_low', 'ci95_high') and layout.LENGTH == 108
    # std_msgs/MultiArrayLayout: dim[0].stride is the whole size, each stride the product of the sizes within it
    sizes = [size for _, size, _ in layout.DIMS]
    assert [stride for _, _, stride in layout.DIMS] == [int(np.prod(sizes[i:])) for i in range(3)]


def test_encode_then_decode_is_the_same_matrices_bit_for_bit() -> None:
    k, low, high = _matrices()
    data = layout.encode(k, low, high)
    assert len(data) == 108 and all(type(v) is float for v in data)
    cube = layout.decode(data)
    assert cube.shape == (3, 6, 6)
    for got, sent in zip(cube, (k, low, high)):
        np.testing.assert_array_equal(got, sent)
    np.testing.assert_array_equal(layout.decode(np.asarray(data)), cube)  # an array (the bulk decoder's) as well


def test_every_entry_sits_where_the_strides_put_it() -> None:
    k, low, high = _matrices()
    data = layout.encode(k, low, high)
    dim = layout.DIMS
    for q, matrix in enumerate((k, low, high)):
        for i in range(6):
            for j in range(6):
                n = dim[1][2] * q + dim[2][2] * i + j  # data_offset 0
                assert layout.index(q, i, j) == layout.index(layout.QUANTITIES[q], i, j) == n
                assert layout.entry(n) == (layout.QUANTITIES[q], i, j)
                assert data[n] == matrix[i, j]
    # the diagonal of K a Foxglove plot reads: data[0], data[7], ... data[35]; its interval 36 and 72 further on
    assert [layout.index('value', i, i) for i in range(6)] == [0, 7, 14, 21, 28, 35]
    assert [layout.index('ci95_high', i, i) for i in range(6)] == [72, 79, 86, 93, 100, 107]


def test_the_ros_message_carries_the_layout_and_decodes_back() -> None:
    msg_mod = pytest.importorskip('std_msgs.msg')
    k, low, high = _matrices(7)
    msg = layout.to_message(k, low, high)
    assert isinstance(msg, msg_mod.Float64MultiArray)
    assert [(d.label, d.size, d.stride) for d in msg.layout.dim] == list(layout.DIMS)
    assert msg.layout.data_offset == 0
    np.testing.assert_array_equal(layout.decode_message(msg), np.stack([k, low, high]))
    # the classes passed in are the ones used (the module imports none itself)
    same = layout.to_message(k, low, high, msg_mod.Float64MultiArray, msg_mod.MultiArrayDimension)
    assert list(same.data) == list(msg.data) and same.layout == msg.layout


def test_wrong_shapes_and_foreign_layouts_are_refused_by_name() -> None:
    k, low, high = _matrices()
    with pytest.raises(layout.LayoutError, match='108'):
        layout.decode([1.0] * 36)
    with pytest.raises(ValueError, match=r'ci95_high has shape \(3, 3\)'):
        layout.encode(k, low, high[:3, :3])
    with pytest.raises(layout.LayoutError):
        layout.index('value', 6, 0)
    with pytest.raises(layout.LayoutError):
        layout.index('median', 0, 0)
    with pytest.raises(layout.LayoutError):
        layout.entry(108)

    # a row-major 18 x 6 of the same 108 numbers (duck-typed like a Float64MultiArray): not this layout
    foreign = SimpleNamespace(layout=SimpleNamespace(dim=[SimpleNamespace(label='row', size=18, stride=108),
                                                          SimpleNamespace(label='column', size=6, stride=6)],
                                                     data_offset=0), data=layout.encode(k, low, high))
    with pytest.raises(layout.LayoutError, match='laid out as'):
        layout.decode_message(foreign)


def test_the_module_imports_no_ros() -> None:
    run_without_ros('''
        import crane_stiffness.contract.stiffness6_layout as layout
        layout.decode(layout.encode(*[[[0.0] * 6] * 6] * 3))
    ''', blocked=('rclpy', 'std_msgs'))
