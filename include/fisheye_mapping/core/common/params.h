// Stage parameters from any key/value source (no ROS): one reading of each
// stage's parameter names serves both the nodelets (ROS parameter server) and
// the offline tools (YAML files such as config/depth.yaml).
#ifndef FISHEYE_MAPPING_CORE_COMMON_PARAMS_H_
#define FISHEYE_MAPPING_CORE_COMMON_PARAMS_H_

#include <map>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include <yaml-cpp/yaml.h>

namespace fisheye_mapping {

/// A source of named parameters; get() leaves `v` alone and returns false when
/// the key is absent, and throws std::invalid_argument naming the key when its
/// value has the wrong type.
class ParamSource {
 public:
  virtual ~ParamSource() = default;
  virtual bool get(const std::string& key, double& v) const = 0;
  virtual bool get(const std::string& key, int& v) const = 0;
  virtual bool get(const std::string& key, bool& v) const = 0;
  virtual bool get(const std::string& key, std::string& v) const = 0;
  virtual bool get(const std::string& key, std::vector<double>& v) const = 0;
  virtual bool get(const std::string& key, std::vector<std::string>& v) const = 0;
  virtual bool get(const std::string& key, std::map<std::string, std::string>& v) const = 0;
  /// get() for a float field (read as double).
  bool get(const std::string& key, float& v) const {
    double d = v;
    if (!get(key, d)) return false;
    v = static_cast<float>(d);
    return true;
  }
};

/// Parameters from an in-memory table (tests, dynamic_reconfigure values):
/// every value a double, an int, a bool, a string, a list or a map; reading a key with
/// another type throws std::invalid_argument naming the key (ints read as
/// doubles too).
class MapParams : public ParamSource {
 public:
  void set(const std::string& key, double v) { d_[key] = v; }
  void set(const std::string& key, int v) { i_[key] = v; }
  void set(const std::string& key, bool v) { b_[key] = v; }
  void set(const std::string& key, const std::string& v) { s_[key] = v; }
  void set(const std::string& key, const char* v) { s_[key] = v; }
  void set(const std::string& key, std::vector<double> v) { vd_[key] = std::move(v); }
  void set(const std::string& key, std::vector<std::string> v) { vs_[key] = std::move(v); }
  void set(const std::string& key, std::map<std::string, std::string> v) { ms_[key] = std::move(v); }
  bool get(const std::string& key, double& v) const override {
    if (auto it = d_.find(key); it != d_.end()) return v = it->second, true;
    if (auto it = i_.find(key); it != i_.end()) return v = it->second, true;
    return absent(key);
  }
  bool get(const std::string& key, int& v) const override { return find(i_, key, v); }
  bool get(const std::string& key, bool& v) const override { return find(b_, key, v); }
  bool get(const std::string& key, std::string& v) const override { return find(s_, key, v); }
  bool get(const std::string& key, std::vector<double>& v) const override { return find(vd_, key, v); }
  bool get(const std::string& key, std::vector<std::string>& v) const override { return find(vs_, key, v); }
  bool get(const std::string& key, std::map<std::string, std::string>& v) const override { return find(ms_, key, v); }
  using ParamSource::get;

 private:
  template <class M, class T>
  bool find(const M& m, const std::string& key, T& v) const {
    if (auto it = m.find(key); it != m.end()) return v = it->second, true;
    return absent(key);
  }
  bool absent(const std::string& key) const {
    if (d_.count(key) || i_.count(key) || b_.count(key) || s_.count(key) || vd_.count(key) || vs_.count(key) ||
        ms_.count(key))
      throw std::invalid_argument("parameter '" + key + "' has the wrong type");
    return false;
  }
  std::map<std::string, double> d_;
  std::map<std::string, int> i_;
  std::map<std::string, bool> b_;
  std::map<std::string, std::string> s_;
  std::map<std::string, std::vector<double>> vd_;
  std::map<std::string, std::vector<std::string>> vs_;
  std::map<std::string, std::map<std::string, std::string>> ms_;
};

/// Parameters from a YAML map (e.g. one stage's section of config/vehicle.yaml).
class YamlParams : public ParamSource {
 public:
  explicit YamlParams(YAML::Node node, std::string origin = "YAML") : node_(std::move(node)), origin_(std::move(origin)) {}
  bool get(const std::string& key, double& v) const override { return read(key, v); }
  bool get(const std::string& key, int& v) const override { return read(key, v); }
  bool get(const std::string& key, bool& v) const override { return read(key, v); }
  bool get(const std::string& key, std::string& v) const override { return read(key, v); }
  bool get(const std::string& key, std::vector<double>& v) const override { return read(key, v); }
  bool get(const std::string& key, std::vector<std::string>& v) const override { return read(key, v); }
  bool get(const std::string& key, std::map<std::string, std::string>& v) const override { return read(key, v); }
  using ParamSource::get;

 private:
  template <class T>
  bool read(const std::string& key, T& v) const {
    if (!node_.IsMap() || !node_[key]) return false;
    try {
      v = node_[key].as<T>();
    } catch (const YAML::Exception&) {
      throw std::invalid_argument(origin_ + ": parameter '" + key + "' has the wrong type");
    }
    return true;
  }
  YAML::Node node_;
  std::string origin_;
};

/// For validate(): throws std::invalid_argument "<field>: <what>, got <value>"
/// unless `ok`.
inline void requireField(bool ok, const std::string& field, const std::string& what, double value) {
  if (ok) return;
  std::ostringstream s;
  s << field << ": " << what << ", got " << value;
  throw std::invalid_argument(s.str());
}

}  // namespace fisheye_mapping

#endif  // FISHEYE_MAPPING_CORE_COMMON_PARAMS_H_
