// Binding plain structs (options, summaries, results) field by field, with a
// readable __repr__ listing the fields and, for options, keyword construction
// (SubspaceOptions(rho_scale=2.0, augment=False)).
#pragma once

#include <qpreduce/report.h>

#include <pybind11/pybind11.h>

#include <string>
#include <utility>
#include <vector>

namespace qpreduce::python {

namespace py = pybind11;

// A summary's report (Outcome::report()) as a dict: reals, ints, bools and
// texts as themselves, lists as lists, nested reports as dicts.
py::dict report_dict(const Report& report);

// "Name(field=value, ...)": enums print as Status.Success, the rest by repr().
std::string fields_repr(py::handle self, const std::string& type_name, const std::vector<std::string>& names);
// Sets each keyword on `self`; TypeError naming an unknown one.
void set_fields(py::handle self, const std::string& type_name, const std::vector<std::string>& names,
                const py::kwargs& kwargs);

// validate(): raises ValueError with is_valid's reason.
template <typename Class, typename T>
void def_validate(Class& cls) {
  cls.def(
      "validate",
      [](const T& options) {
        std::string why;
        if (!options.is_valid(&why)) throw py::value_error(why);
      },
      "Raises ValueError saying why when the options are invalid (the C++ is_valid).");
}

template <typename Class>
class Fields {
 public:
  Fields(Class& cls, std::string type_name) : cls_(cls), type_name_(std::move(type_name)) {}

  template <typename D, typename C>
  Fields& rw(const char* name, D C::*member, const char* doc) {
    cls_.def_readwrite(name, member, doc);
    names_.emplace_back(name);
    return *this;
  }
  template <typename D, typename C>
  Fields& ro(const char* name, D C::*member, const char* doc) {
    cls_.def_readonly(name, member, doc);
    names_.emplace_back(name);
    return *this;
  }
  // A name already bound (a property or a field of a base class) that the
  // repr should list.
  Fields& listed(const char* name) {
    names_.emplace_back(name);
    return *this;
  }
  // __repr__ over the fields listed so far.
  Fields& repr() {
    cls_.def("__repr__", [names = names_, type_name = type_name_](py::handle self) {
      return fields_repr(self, type_name, names);
    });
    return *this;
  }
  // __init__(**kwargs) over the fields listed so far (defaults otherwise).
  template <typename T>
  Fields& keyword_init() {
    cls_.def(py::init([names = names_, type_name = type_name_](const py::kwargs& kwargs) {
               py::object object = py::cast(T{});
               set_fields(object, type_name, names, kwargs);
               return object.cast<T>();
             }),
             "Keyword construction; every field not given keeps its default.");
    return *this;
  }

 private:
  Class& cls_;
  std::string type_name_;
  std::vector<std::string> names_;
};

}  // namespace qpreduce::python
