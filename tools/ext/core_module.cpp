// graspguide._core: the GraspGuide C++ core (lib/graspguide) for Python, via nanobind.
//
// Only graspguide::Guidance<float> and Guidance<double> are instantiated here; the heavy
// templates (QR, SVD, QP, steps 1-6) are `extern template` in the core's headers and
// compiled once in lib/graspguide/src/*.cpp, which CMake links into this module.
//
// Python types are converted by nanobind (a wrong type or length raises TypeError); the
// names of policies, modes, models, scalars and decompositions raise ValueError listing
// the accepted ones. Every number, NaN and infinities included, is handed to the core,
// which answers with a Status: nothing here reads a value to decide anything else.
#include <nanobind/nanobind.h>
#include <nanobind/stl/array.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <array>
#include <memory>
#include <string>
#include <vector>

#include "graspguide.h"

namespace nb = nanobind;
using namespace nb::literals;
namespace gg = graspguide;

namespace {

using ContactList = std::vector<std::array<double, 3>>;
using Wrench = std::array<double, 6>;
using Quat4 = std::array<double, 4>;
using Axis3 = std::array<double, 3>;

// The statuses are contiguous from kOk to the last one (status.h keeps kStatusCount).
inline gg::Status status_at(int i) { return static_cast<gg::Status>(i); }

constexpr const char* decomposition_name(gg::Decomposition d) {
  return d == gg::Decomposition::kQR ? "qr" : "svd";
}

// A name for an error message: printable ASCII, at most 40 characters (the message
// goes through a C string, so an embedded NUL would cut it).
std::string shown(const std::string& s) {
  static const char* hex = "0123456789abcdef";
  std::string out;
  for (unsigned char c : s) {
    if (out.size() >= 40) { out += "..."; break; }
    if (c >= 0x20 && c < 0x7f && c != '\\') {
      out += static_cast<char>(c);
    } else {
      out += "\\x";
      out += hex[c >> 4];
      out += hex[c & 15];
    }
  }
  return out;
}

// Exact, case-sensitive name lookup (std::string comparison, so an embedded NUL never
// matches a shorter name).
template <typename E, std::size_t N>
E parse_name(const std::string& s, const E (&values)[N], const char* (*name)(E),
             const char* what) {
  for (E v : values)
    if (s == name(v)) return v;
  std::string accepted;
  for (std::size_t i = 0; i < N; ++i) {
    accepted += i ? ", '" : "'";
    accepted += name(values[i]);
    accepted += "'";
  }
  throw nb::value_error(
      (std::string("unknown ") + what + " '" + shown(s) + "'; accepted: " + accepted).c_str());
}

constexpr gg::Policy kPolicies[] = {gg::Policy::kF, gg::Policy::kFperp};
constexpr gg::Mode kModes[] = {gg::Mode::kC, gg::Mode::kV};
constexpr gg::ConstraintModel kModels[] = {gg::ConstraintModel::kPaper,
                                           gg::ConstraintModel::kNormal,
                                           gg::ConstraintModel::kNone};
constexpr gg::Decomposition kDecompositions[] = {gg::Decomposition::kQR,
                                                 gg::Decomposition::kSVD};

const char* policy_name_fn(gg::Policy p) { return gg::policy_name(p); }
const char* mode_name_fn(gg::Mode m) { return gg::mode_name(m); }
const char* model_name_fn(gg::ConstraintModel m) { return gg::constraint_model_name(m); }
const char* decomposition_name_fn(gg::Decomposition d) { return decomposition_name(d); }

struct SceneOptions {
  gg::Policy policy = gg::Policy::kF;
  gg::Mode mode = gg::Mode::kC;
  gg::ConstraintModel constraints = gg::ConstraintModel::kPaper;
  gg::Decomposition decomposition = gg::Decomposition::kQR;
  int max_iterations = gg::kDefaultMaxIterations;
};

SceneOptions parse_options(const std::string& policy, const std::string& mode,
                           const std::string& constraints, const std::string& decomposition,
                           int max_iterations) {
  SceneOptions o;
  o.policy = parse_name(policy, kPolicies, policy_name_fn, "policy");
  o.mode = parse_name(mode, kModes, mode_name_fn, "mode");
  o.constraints = parse_name(constraints, kModels, model_name_fn, "constraint model");
  o.decomposition = parse_name(decomposition, kDecompositions, decomposition_name_fn,
                               "decomposition");
  o.max_iterations = max_iterations;  // < 1 is the core's bad_config
  return o;
}

// The contact count is passed on as given (capped, so it fits an int): the core answers
// bad_contact_count for anything but 3 or 4. Only the first kMaxContacts are copied.
int contact_count(const ContactList& contacts) {
  return static_cast<int>(std::min<std::size_t>(contacts.size(), 1u << 20));
}

template <typename T>
void fill_contacts(const ContactList& contacts, Eigen::Matrix<T, 3, gg::kMaxContacts>& out) {
  out.setZero();
  const int n = std::min<int>(contact_count(contacts), gg::kMaxContacts);
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < 3; ++j) out(j, i) = static_cast<T>(contacts[i][j]);
}

template <typename T>
gg::Scene<T> make_scene(const ContactList& contacts, const Axis3& y_axis, const SceneOptions& o) {
  gg::Scene<T> s;
  s.k = contact_count(contacts);
  fill_contacts<T>(contacts, s.contacts);
  s.y_axis = gg::Vec3<T>(static_cast<T>(y_axis[0]), static_cast<T>(y_axis[1]),
                         static_cast<T>(y_axis[2]));
  s.constraints = o.constraints;
  s.policy = o.policy;
  s.mode = o.mode;
  s.solver.decomposition = o.decomposition;
  s.solver.max_iterations = o.max_iterations;
  return s;
}

template <typename T>
gg::Vec6<T> make_wrench(const Wrench& w) {
  gg::Vec6<T> v;
  for (int i = 0; i < 6; ++i) v(i) = static_cast<T>(w[i]);
  return v;
}

template <typename T>
Eigen::Matrix<T, 4, 1> make_quat(const Quat4& q) {
  return Eigen::Matrix<T, 4, 1>(static_cast<T>(q[0]), static_cast<T>(q[1]),
                                static_cast<T>(q[2]), static_cast<T>(q[3]));
}

// The result of one frame as a dict. Outputs that the status leaves undefined are None
// (levels, lambda, relevant, error_deg, alpha) or "" (constraints_used); pwm is always k
// ints, all 0 unless the status is ok. iterations and rank_ratio describe the last grasp
// computation (0 if it did not get that far).
template <typename T>
nb::dict result_dict(gg::Status status, int k, const gg::FrameResult<T>& fr,
                     const gg::GraspSolution<T>& g) {
  const bool ok = status == gg::Status::kOk;
  nb::dict d;
  d["status"] = gg::status_name(status);
  nb::list pwm;
  for (int i = 0; i < k; ++i) pwm.append(ok && i < gg::kMaxContacts ? int(fr.pwm.duty[i]) : 0);
  d["pwm"] = pwm;
  if (ok) {
    nb::list levels, lambda, relevant;
    for (int i = 0; i < k; ++i) {
      levels.append(double(g.levels(i)));
      relevant.append(bool(g.relevant_mask & (1u << i)));
      for (int j = 0; j < 3; ++j) lambda.append(double(g.lambda(3 * i + j)));
    }
    d["levels"] = levels;
    d["lambda"] = lambda;
    d["constraints_used"] = gg::constraint_model_name(g.used);
    d["relevant"] = relevant;
    d["error_deg"] = double(fr.error_deg);
    d["alpha"] = double(fr.alpha);
    d["fallback_mask"] = int(g.fallback_mask);
  } else {
    d["levels"] = nb::none();
    d["lambda"] = nb::none();
    d["constraints_used"] = "";
    d["relevant"] = nb::none();
    d["error_deg"] = nb::none();
    d["alpha"] = nb::none();
    d["fallback_mask"] = 0;
  }
  d["iterations"] = g.iterations;
  d["rank_ratio"] = double(g.rank_ratio);
  d["recomputed"] = fr.recomputed;
  return d;
}

// One-shot Algorithm 1 through Guidance<T>::solve, which checks in one order whatever is
// wrong: non-finite input, contact count, axis, quaternion, then the geometry.
template <typename T>
nb::dict solve_t(const ContactList& contacts, const Wrench& wrench, const SceneOptions& o,
                 const Quat4& orientation, const Axis3& y_axis) {
  gg::Guidance<T> guidance;
  gg::FrameResult<T> fr;
  const gg::Status s = guidance.solve(make_scene<T>(contacts, y_axis, o), make_wrench<T>(wrench),
                                      make_quat<T>(orientation), fr);
  return result_dict<T>(s, contact_count(contacts), fr, guidance.grasp());
}

nb::dict solve(const ContactList& contacts, const Wrench& wrench, const std::string& policy,
               const std::string& mode, const std::string& constraints,
               const Quat4& orientation, const Axis3& y_axis, const std::string& scalar,
               const std::string& decomposition, int max_iterations) {
  const SceneOptions o = parse_options(policy, mode, constraints, decomposition, max_iterations);
  if (scalar == "double") return solve_t<double>(contacts, wrench, o, orientation, y_axis);
  if (scalar == "float") return solve_t<float>(contacts, wrench, o, orientation, y_axis);
  throw nb::value_error(
      ("unknown scalar '" + shown(scalar) + "'; accepted: 'double', 'float'").c_str());
}

// Stateful guidance in double, as the firmware runs it frame by frame.
class PyGuidance {
 public:
  PyGuidance() : g_(std::make_unique<gg::Guidance<double>>()) {}

  std::string set_scene(const ContactList& contacts, const std::string& policy,
                        const std::string& mode, const std::string& constraints,
                        const Axis3& y_axis, const std::string& decomposition,
                        int max_iterations) {
    const SceneOptions o =
        parse_options(policy, mode, constraints, decomposition, max_iterations);
    return gg::status_name(g_->set_scene(make_scene<double>(contacts, y_axis, o)));
  }

  std::string set_wrench(const Wrench& wrench) {
    return gg::status_name(g_->set_wrench(make_wrench<double>(wrench)));
  }

  // The count must stay the scene's k (change it with set_scene).
  std::string set_contacts(const ContactList& contacts) {
    if (contact_count(contacts) != g_->scene().k)
      return gg::status_name(gg::Status::kBadContactCount);
    Eigen::Matrix<double, 3, gg::kMaxContacts> c;
    fill_contacts<double>(contacts, c);
    return gg::status_name(g_->set_contacts(c));
  }

  nb::dict update(const Quat4& orientation) {
    gg::FrameResult<double> fr;
    const gg::Status s = g_->update(make_quat<double>(orientation), fr);
    return result_dict<double>(s, g_->scene().k, fr, g_->grasp());
  }

  int k() const { return g_->scene().k; }

 private:
  std::unique_ptr<gg::Guidance<double>> g_;  // heap: Eigen members need 16-byte alignment
};

nb::dict tolerances(bool is_float) {
  nb::dict d;
  d["kCoincidentRelTol"] = gg::kCoincidentRelTol;
  d["kAxisParallelTol"] = gg::kAxisParallelTol;
  d["kRankRelTol"] = gg::kRankRelTol;
  d["kZeroForceRelTol"] = gg::kZeroForceRelTol;
  d["kRelevanceCosTol"] = gg::kRelevanceCosTol;
  d["kTinyRel"] = gg::kTinyRel;
  d["kFeasRelTol"] = is_float ? double(gg::Tolerances<float>::kFeasRel)
                              : gg::Tolerances<double>::kFeasRel;
  d["kDependentRelTol"] = is_float ? double(gg::Tolerances<float>::kDependentRel)
                                   : gg::Tolerances<double>::kDependentRel;
  d["kMotorOffLevel"] = gg::kMotorOffLevel;
  d["kMinQuaternionNorm"] = gg::kMinQuaternionNorm;
  return d;
}

constexpr const char* kResultDoc =
    "dict with keys: status (str, 'ok' or an error name from STATUS_NAMES), pwm (k ints, "
    "all 0 unless ok), levels (k floats: normalised motor levels m, signed for Fperp), "
    "lambda (3k floats: contact forces [x y z] per contact before normalisation), "
    "constraints_used ('paper'/'normal'/'none', '' unless ok), relevant (k bools), "
    "error_deg, alpha (floats), fallback_mask (int), iterations (int: QP active-set "
    "changes), rank_ratio (float), recomputed (bool: the grasp part ran). levels, lambda, "
    "relevant, error_deg and alpha are None unless status is 'ok'.";

}  // namespace

NB_MODULE(_core, m) {
  m.doc() =
      "GraspGuide C++ core (lib/graspguide): Algorithm 1 in float or double. "
      "See docs/algorithm.md.";

  nb::list names;
  nb::dict messages;
  for (int i = 0; i < gg::kStatusCount; ++i) {
    const gg::Status s = status_at(i);
    names.append(gg::status_name(s));
    messages[gg::status_name(s)] = gg::status_message(s);
  }
  m.attr("STATUS_NAMES") = nb::tuple(names);
  m.attr("STATUS_MESSAGES") = messages;
  m.attr("POLICIES") = nb::make_tuple("F", "Fperp");
  m.attr("MODES") = nb::make_tuple("C", "V");
  m.attr("CONSTRAINT_MODELS") = nb::make_tuple("paper", "normal", "none");
  m.attr("DECOMPOSITIONS") = nb::make_tuple("qr", "svd");
  m.attr("SCALARS") = nb::make_tuple("double", "float");
  m.attr("kPwmMin") = gg::kPwmMin;
  m.attr("kPwmSpan") = gg::kPwmSpan;
  m.attr("kMinContacts") = gg::kMinContacts;
  m.attr("kMaxContacts") = gg::kMaxContacts;
  m.attr("kDefaultMaxIterations") = gg::kDefaultMaxIterations;
  nb::dict tol;
  tol["double"] = tolerances(false);
  tol["float"] = tolerances(true);
  m.attr("TOLERANCES") = tol;

  m.def(
      "status_message",
      [](const std::string& name) -> std::string {
        for (int i = 0; i < gg::kStatusCount; ++i)
          if (name == gg::status_name(status_at(i))) return gg::status_message(status_at(i));
        throw nb::value_error(("unknown status name '" + shown(name) + "'").c_str());
      },
      "name"_a, "What a status means and how to fix it (status.h's status_message).");

  m.def("solve", &solve, "contacts"_a, "wrench"_a, "policy"_a = "F", "mode"_a = "C",
        "constraints"_a = "paper", "orientation"_a = Quat4{1.0, 0.0, 0.0, 0.0},
        "y_axis"_a = Axis3{0.0, 1.0, 0.0}, "scalar"_a = "double", "decomposition"_a = "qr",
        "max_iterations"_a = gg::kDefaultMaxIterations,
        (std::string(
             "Run Algorithm 1 once with graspguide::Guidance<T>::solve (scene, wrench and "
             "orientation in one call).\n\n"
             "contacts: k triples [x, y, z] in the hand frame (k must be 3 or 4, anything "
             "else is status bad_contact_count); wrench: [fx, fy, fz, mx, my, mz] in the "
             "object frame; policy 'F' | 'Fperp'; mode 'C' | 'V'; constraints 'paper' | "
             "'normal' | 'none'; orientation: [w, x, y, z] hand -> world; y_axis: y_O in "
             "the hand frame; scalar 'double' | 'float'; decomposition 'qr' | 'svd'; "
             "max_iterations: QP cap (< 1 is bad_config).\n\nReturns a ") +
         kResultDoc)
            .c_str());

  nb::class_<PyGuidance>(m, "Guidance",
                         "Stateful Algorithm 1 in double (graspguide::Guidance<double>): the "
                         "grasp part is kept until the contacts, the wrench or the scene "
                         "change, so update() with only a new orientation is cheap. Setters "
                         "return a status name ('ok' or the error; on error nothing changes).")
      .def(nb::init<>())
      .def("set_scene", &PyGuidance::set_scene, "contacts"_a, "policy"_a = "F", "mode"_a = "C",
           "constraints"_a = "paper", "y_axis"_a = Axis3{0.0, 1.0, 0.0},
           "decomposition"_a = "qr", "max_iterations"_a = gg::kDefaultMaxIterations,
           "Set the contacts (3 or 4 triples) and the scene's parameters; forces a "
           "recomputation. Returns a status name.")
      .def("set_wrench", &PyGuidance::set_wrench, "wrench"_a,
           "Set [fx, fy, fz, mx, my, mz]; a different wrench forces a recomputation. Returns "
           "a status name.")
      .def("set_contacts", &PyGuidance::set_contacts, "contacts"_a,
           "New contact positions (same count as the scene); exactly equal contacts do not "
           "force a recomputation. Returns a status name.")
      .def("update", &PyGuidance::update, "orientation"_a = Quat4{1.0, 0.0, 0.0, 0.0},
           (std::string("One frame for the hand orientation [w, x, y, z]. Returns a ") +
            kResultDoc)
               .c_str())
      .def_prop_ro("k", &PyGuidance::k, "The scene's contact count.");
}
