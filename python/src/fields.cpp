#include "fields.h"

#include <pybind11/stl.h>

#include <algorithm>
#include <type_traits>
#include <variant>

namespace qpreduce::python {

py::dict report_dict(const Report& report) {
  py::dict out;
  for (const Report::Entry& e : report.entries()) {
    out[py::str(e.key)] = std::visit(
        [](const auto& v) -> py::object {
          using T = std::decay_t<decltype(v)>;
          if constexpr (std::is_same_v<T, std::shared_ptr<const Report>>) return report_dict(*v);
          else return py::cast(v);
        },
        e.value);
  }
  return out;
}

std::string fields_repr(py::handle self, const std::string& type_name, const std::vector<std::string>& names) {
  std::string text = type_name + "(";
  for (std::size_t i = 0; i < names.size(); ++i) {
    const py::object value = self.attr(names[i].c_str());
    const bool is_enum = py::hasattr(py::type::of(value), "__members__");
    text += (i ? ", " : "") + names[i] + "=" + py::str(is_enum ? py::str(value) : py::repr(value)).cast<std::string>();
  }
  return text + ")";
}

void set_fields(py::handle self, const std::string& type_name, const std::vector<std::string>& names,
                const py::kwargs& kwargs) {
  for (const auto& item : kwargs) {
    const auto key = item.first.cast<std::string>();
    if (std::find(names.begin(), names.end(), key) == names.end()) {
      throw py::type_error(type_name + ": unknown keyword '" + key + "'");
    }
    py::setattr(self, item.first, item.second);
  }
}

}  // namespace qpreduce::python
