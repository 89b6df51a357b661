// What geo's Python bindings share: arguments from Python (torch tensors, numpy arrays, anything
// numpy reads) as tensors without copies, and the parts of the module (one file each).
#pragma once

#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <torch/python.h>
#include <torch/torch.h>

#include <map>
#include <string>
#include <vector>

namespace geo::python {

namespace py = pybind11;

// A torch tensor as it is; a numpy array (or anything numpy.asarray reads) as a tensor sharing its
// memory (copied only when torch cannot share it: negative strides, a foreign byte order).
// `what` names the argument in errors.
torch::Tensor tensor_arg(py::handle object, const std::string& what);
// tensor_arg(), or an undefined tensor for None (geo's "not given").
torch::Tensor optional_tensor_arg(py::handle object, const std::string& what);
// An image: torch tensors are geo's [3,H,W] / [B,3,H,W] (channels first); numpy arrays are images
// as imageio, PIL and OpenCV give them, [H,W,3] / [B,H,W,3] (channels last), returned as a
// channels-first view of the same memory.
torch::Tensor image_arg(py::handle object, const std::string& what);

// Python's dict of a name -> number map.
py::dict as_dict(const std::map<std::string, double>& values);

void bind_model(py::module_& m);  // geo.Model (include/geo/geo.h), geo.image
void bind_data(py::module_& m);   // geo.synth, geo.kitti (formats that need no OpenCV)
void bind_eval(py::module_& m);   // geo.eval, geo.io (OpenCV builds)
void bind_train(py::module_& m);  // geo.train, geo.resume, geo.state_dicts

}  // namespace geo::python
