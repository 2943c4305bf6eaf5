// Dev-only oracle: runs a conformance-format case with real BT.CPP and prints the trace as JSON.
#include <behaviortree_cpp/bt_factory.h>
#include <behaviortree_cpp/loggers/abstract_logger.h>
#include <behaviortree_cpp/contrib/json.hpp>
#include <fstream>
#include <iostream>
#include <mutex>
#include <thread>
using json = nlohmann::json;
using namespace BT;

struct Shared {
  json scripts;
  std::map<std::string, int> counters;
  std::mutex m;
  json calls = json::array();
};

static NodeStatus toStatus(const std::string& s) {
  if (s == "SUCCESS") return NodeStatus::SUCCESS;
  if (s == "FAILURE") return NodeStatus::FAILURE;
  return NodeStatus::RUNNING;
}

template <class Base>
class Scripted : public Base {
 public:
  Scripted(const std::string& name, const NodeConfig& cfg, Shared* sh, std::vector<std::string> inputs)
      : Base(name, cfg), sh_(sh), inputs_(std::move(inputs)) {}
  NodeStatus step(const char* call) {
    const std::string path = this->fullPath();
    json steps = sh_->scripts.contains(path) ? sh_->scripts[path] : json::array({"SUCCESS"});
    int k;
    {
      std::lock_guard<std::mutex> lk(sh_->m);
      k = sh_->counters[path]++;
    }
    json st0 = steps[std::min<size_t>(k, steps.size() - 1)];
    json st = json::object();
    if (st0.is_string()) st["status"] = st0; else st = st0;
    json rec = json::array({path, call, st["status"].get<std::string>()});
    if (!inputs_.empty()) {
      json in = json::object();
      for (auto& p : inputs_) {
        auto r = this->template getInput<std::string>(p);
        in[p] = r ? json(r.value()) : json(nullptr);
      }
      rec.push_back(in);
    }
    if (st.contains("outputs")) {
      for (auto& [key, v] : st["outputs"].items()) {
        if (v.is_string()) this->setOutput(key, v.template get<std::string>());
        else if (v.is_boolean()) this->setOutput(key, v.template get<bool>());
        else if (v.is_number_integer()) this->setOutput(key, v.template get<int>());
        else if (v.is_number_float()) this->setOutput(key, v.template get<double>());
      }
    }
    {
      std::lock_guard<std::mutex> lk(sh_->m);
      sh_->calls.push_back(rec);
    }
    return toStatus(st["status"].get<std::string>());
  }
 protected:
  Shared* sh_;
  std::vector<std::string> inputs_;
};

class ScriptedAction : public Scripted<StatefulActionNode> {
 public:
  using Scripted::Scripted;
  NodeStatus onStart() override { return step("onStart"); }
  NodeStatus onRunning() override { return step("onRunning"); }
  void onHalted() override {
    std::lock_guard<std::mutex> lk(sh_->m);
    sh_->calls.push_back(json::array({fullPath(), "onHalted"}));
  }
};
class ScriptedCond : public Scripted<ConditionNode> {
 public:
  using Scripted::Scripted;
  NodeStatus tick() override { return step("tick"); }
};

class Rec : public StatusChangeLogger {
 public:
  Rec(TreeNode* root, Shared* sh) : StatusChangeLogger(root), sh_(sh) {}
  void callback(Duration, const TreeNode& node, NodeStatus prev, NodeStatus st) override {
    std::lock_guard<std::mutex> lk(sh_->m);
    trans.push_back(json::array({node.fullPath(), toStr(prev), toStr(st)}));
  }
  void flush() override {}
  json trans = json::array();
  Shared* sh_;
};

static json anyToJson(const Any& a) {
  if (a.empty()) return nullptr;
  if (a.isString()) return a.cast<std::string>();
  if (a.isType<bool>()) return a.cast<bool>();
  if (a.isIntegral()) return a.cast<int64_t>();
  if (a.isNumber()) return a.cast<double>();
  return std::string("<") + demangle(a.type()) + ">";
}

int main(int argc, char** argv) {
  std::ifstream f(argv[1]);
  json c = json::parse(f);
  std::string mode = argc > 2 ? argv[2] : "once";
  bool v3 = argc > 3 && std::string(argv[3]) == "v3";
  Shared sh;
  sh.scripts = c.value("leaf_scripts", json::object());
  BehaviorTreeFactory factory;
  json types = c.value("node_types", json::object());
  if (!types.contains("Leaf")) types["Leaf"] = json{{"kind", "action"}};
  if (!types.contains("Cond")) types["Cond"] = json{{"kind", "condition"}};
  for (auto& [id, spec] : types.items()) {
    PortsList ports;
    std::vector<std::string> inputs;
    json portspecs = spec.value("ports", json::object());
    for (auto& [pname, pspec] : portspecs.items()) {
      std::string dir = pspec.is_string() ? pspec.get<std::string>() : pspec["direction"].get<std::string>();
      PortDirection d = dir == "input" ? PortDirection::INPUT : dir == "output" ? PortDirection::OUTPUT : PortDirection::INOUT;
      PortInfo info(d);
      if (pspec.is_object() && pspec.contains("default")) info.setDefaultValue(pspec["default"].get<std::string>());
      ports.insert({pname, info});
      if (d != PortDirection::OUTPUT) inputs.push_back(pname);
    }
    bool action = spec["kind"] == "action";
    TreeNodeManifest manifest{action ? NodeType::ACTION : NodeType::CONDITION, id, ports, {}};
    NodeBuilder b = [&sh, inputs, action](const std::string& name, const NodeConfig& cfg) -> std::unique_ptr<TreeNode> {
      if (action) return std::make_unique<ScriptedAction>(name, cfg, &sh, inputs);
      return std::make_unique<ScriptedCond>(name, cfg, &sh, inputs);
    };
    factory.registerBuilder(manifest, b);
  }
  json out;
  out["trace"] = json::array();
  Tree tree;
  try {
    factory.registerBehaviorTreeFromText(c[v3 ? "xml_v3" : "xml"].get<std::string>());
    tree = (c.contains("main_tree") && c["main_tree"].is_string()) ? factory.createTree(c["main_tree"].get<std::string>()) : factory.createTree("");
  } catch (std::exception& e) {
    out["load_error"] = e.what();
    std::cout << out.dump() << std::endl;
    return 0;
  }
  Rec rec(tree.rootNode(), &sh);
  int ticks = c["ticks"];
  json sleeps = c.value("sleep_before_tick_ms", json::array());
  for (int i = 0; i < ticks; i++) {
    int ms = i < (int)sleeps.size() ? sleeps[i].get<int>() : 0;
    if (ms > 0) std::this_thread::sleep_for(std::chrono::milliseconds(ms));
    json entry;
    entry["tick"] = i + 1;
    {
      std::lock_guard<std::mutex> lk(sh.m);
      if (!rec.trans.empty()) entry["between_transitions"] = rec.trans;
      if (!sh.calls.empty()) entry["between_leaf_calls"] = sh.calls;
      rec.trans = json::array();
      sh.calls = json::array();
    }
    try {
      NodeStatus s = mode == "once" ? tree.tickOnce() : tree.tickExactlyOnce();
      entry["root_status"] = toStr(s);
    } catch (std::exception& e) {
      entry["root_status"] = nullptr;
      entry["error"] = e.what();
    }
    {
      std::lock_guard<std::mutex> lk(sh.m);
      entry["transitions"] = rec.trans;
      entry["leaf_calls"] = sh.calls;
      rec.trans = json::array();
      sh.calls = json::array();
    }
    out["trace"].push_back(entry);
    if (entry.contains("error")) break;
  }
  json bb = json::object();
  auto root = tree.rootBlackboard();
  for (auto k : root->getKeys()) {
    auto e = root->getEntry(std::string(k));
    bb[std::string(k)] = anyToJson(e->value);
  }
  out["blackboard"] = bb;
  std::cout << out.dump() << std::endl;
  return 0;
}
