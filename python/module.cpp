// The extension module geo._geo; the package geo (python/geo/__init__.py) re-exports it.
#include "bindings.h"

#include "core/config.h"
#include "geo/geo.h"

#include <stdexcept>

namespace geo::python {

torch::Tensor tensor_arg(py::handle object, const std::string& what) {
  if (THPVariable_Check(object.ptr())) return py::cast<torch::Tensor>(object);
  py::module_ np = py::module_::import("numpy");
  py::object array;
  try {
    array = np.attr("asarray")(object);
  } catch (py::error_already_set& e) {
    throw Error(what + ": not a torch tensor nor an array numpy reads (" + e.what() + ")");
  }
  const std::string kind = py::str(array.attr("dtype").attr("kind"));
  if (kind == "O" || kind == "U" || kind == "S")
    throw Error(what + ": not a numeric array (numpy dtype " + std::string(py::str(array.attr("dtype"))) + ")");
  bool shareable = py::cast<bool>(array.attr("dtype").attr("isnative"));
  for (auto stride : array.attr("strides")) shareable = shareable && py::cast<int64_t>(stride) >= 0;
  if (!shareable)
    array = np.attr("ascontiguousarray")(array, py::arg("dtype") = array.attr("dtype").attr("newbyteorder")("="));
  // Read-only arrays (PIL's np.asarray) are shared too: geo never writes into its inputs, so torch's
  // warning about writing through the tensor does not apply.
  py::module_ warnings = py::module_::import("warnings");
  py::object guard = warnings.attr("catch_warnings")();
  guard.attr("__enter__")();
  warnings.attr("simplefilter")("ignore");
  torch::Tensor tensor;
  try {
    tensor = py::cast<torch::Tensor>(py::module_::import("torch").attr("from_numpy")(array));
  } catch (py::error_already_set& e) {
    guard.attr("__exit__")(py::none(), py::none(), py::none());
    throw Error(what + ": " + e.what());
  }
  guard.attr("__exit__")(py::none(), py::none(), py::none());
  return tensor;
}

torch::Tensor optional_tensor_arg(py::handle object, const std::string& what) {
  return object.is_none() ? torch::Tensor() : tensor_arg(object, what);
}

torch::Tensor image_arg(py::handle object, const std::string& what) {
  const bool is_tensor = THPVariable_Check(object.ptr());
  torch::Tensor t = tensor_arg(object, what);
  if (is_tensor) return t;
  if (t.dim() == 3 && t.size(2) == 3) return t.permute({2, 0, 1});
  if (t.dim() == 4 && t.size(3) == 3) return t.permute({0, 3, 1, 2});
  std::string shape;
  for (auto s : t.sizes()) shape += (shape.empty() ? "" : "x") + std::to_string(s);
  throw Error(what +
              ": an image array must be HxWx3 or BxHxWx3 RGB (channels last, as imageio, PIL and OpenCV give "
              "them; torch tensors are 3xHxW), got " +
              (shape.empty() ? "a scalar" : shape));
}

py::dict as_dict(const std::map<std::string, double>& values) {
  py::dict d;
  for (const auto& [k, v] : values) d[py::str(k)] = v;
  return d;
}

}  // namespace geo::python

PYBIND11_MODULE(_geo, m) {
  namespace py = pybind11;
  m.doc() = "geo: depth, optical flow and camera motion from monocular video (GeoNet with feature refinement)";
  // Every geo failure is a geo.Error (a RuntimeError) carrying geo's message; a config's is a
  // geo.ConfigError (a geo.Error) naming the key.
  // The module holds the two types (PyErr_SetString rather than py::exception's call operator,
  // which pybind11 2.12 deprecated and 2.10 has no replacement for).
  static PyObject* error = py::exception<geo::Error>(m, "Error", PyExc_RuntimeError).ptr();
  static PyObject* config_error = py::exception<geo::ConfigError>(m, "ConfigError", error).ptr();
  // Local: only for geo's own functions (a global one would turn torch's errors into geo.Error too).
  py::register_local_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const geo::ConfigError& e) {
      PyErr_SetString(config_error, e.what());
    } catch (const geo::Error& e) {
      PyErr_SetString(error, e.what());
    } catch (const c10::Error&) {
      throw;  // torch's own translation (RuntimeError, IndexError, ...)
    } catch (const std::invalid_argument& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    } catch (const std::runtime_error& e) {
      PyErr_SetString(error, e.what());  // geo's readers and checks throw std::runtime_error naming the file or value
    }
  });
  geo::python::bind_model(m);
  geo::python::bind_data(m);
#ifdef GEO_WITH_OPENCV
  geo::python::bind_eval(m);
  m.attr("has_opencv") = true;
#else
  m.attr("has_opencv") = false;
#endif
  geo::python::bind_train(m);
}
