// A ROS 2 peer built on eProsima Fast DDS (ROS 2 Humble's default middleware), independent of the twin.
//
// Its message types are not written here: fastddsgen generates them from ROS 2's message definitions
// in IDL (tests/ros2/idl/, as rosidl_adapter shapes them), with `-typeros2` so that each registers
// under the name rmw_fastrtps gives it (`sensor_msgs::msg::dds_::LaserScan_`); the test compiles this
// file against the generated sources. It joins a DDS domain as rmw_fastrtps would (topics
// `rt/<name>`), reads /scan, /odom, /clock and /tf (best effort: what a sensor-data subscriber asks)
// and publishes /cmd_vel (reliable, as `rclcpp::QoS(10)` does) at 10 Hz. It ends when /clock has been
// silent for 3 s after it started, or at the wall-time limit, and writes what it received as JSON lines.
//
// usage: fastdds_peer DOMAIN OUT.jsonl LINEAR_X ANGULAR_Z MAX_WALL_S

#include "geometry_msgs/msg/TwistPubSubTypes.h"
#include "nav_msgs/msg/OdometryPubSubTypes.h"
#include "rosgraph_msgs/msg/ClockPubSubTypes.h"
#include "sensor_msgs/msg/LaserScanPubSubTypes.h"
#include "tf2_msgs/msg/TFMessagePubSubTypes.h"

#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
#include <string>
#include <thread>
#include <vector>

using namespace eprosima::fastdds::dds;

// The DDS type name rmw_fastrtps_cpp registers for a ROS 2 message `package/msg/Name`.
static std::string rmw_type_name(const std::string& package, const std::string& name) {
    return package + "::msg::dds_::" + name + "_";
}

// A number as JSON (Python's reader): Infinity, -Infinity and NaN for the non-finite (a lidar's "no return").
static std::string number(double v, bool single) {
    if (std::isnan(v)) return "NaN";
    if (std::isinf(v)) return v > 0 ? "Infinity" : "-Infinity";
    char num[64];
    std::snprintf(num, sizeof num, single ? "%.9g" : "%.17g", v);
    return num;
}

static std::string stamp(const builtin_interfaces::msg::Time& t) {
    return ", \"sec\": " + std::to_string(t.sec()) + ", \"nanosec\": " + std::to_string(t.nanosec());
}

static std::string quoted(const std::string& s) { return "\"" + s + "\""; }

static std::string as_json(const sensor_msgs::msg::LaserScan& scan) {
    std::string out = "{\"topic\": \"/scan\"" + stamp(scan.header().stamp());
    out += ", \"frame_id\": " + quoted(scan.header().frame_id());
    out += ", \"angle_min\": " + number(scan.angle_min(), true);
    out += ", \"angle_max\": " + number(scan.angle_max(), true);
    out += ", \"range_max\": " + number(scan.range_max(), true);
    out += ", \"ranges\": [";
    const std::vector<float>& ranges = scan.ranges();
    for (size_t i = 0; i < ranges.size(); ++i) out += (i ? ", " : "") + number(ranges[i], true);
    return out + "]}";
}

static std::string as_json(const nav_msgs::msg::Odometry& odom) {
    std::string out = "{\"topic\": \"/odom\"" + stamp(odom.header().stamp());
    out += ", \"frame_id\": " + quoted(odom.header().frame_id());
    out += ", \"child_frame_id\": " + quoted(odom.child_frame_id());
    out += ", \"x\": " + number(odom.pose().pose().position().x(), false);
    out += ", \"y\": " + number(odom.pose().pose().position().y(), false);
    out += ", \"vx\": " + number(odom.twist().twist().linear().x(), false);
    return out + "}";
}

static std::string as_json(const rosgraph_msgs::msg::Clock& clock) {
    return "{\"topic\": \"/clock\"" + stamp(clock.clock()) + "}";
}

static std::string as_json(const tf2_msgs::msg::TFMessage& tf) {
    std::string out = "{\"topic\": \"/tf\", \"children\": [";
    const auto& transforms = tf.transforms();
    for (size_t i = 0; i < transforms.size(); ++i) out += (i ? ", " : "") + quoted(transforms[i].child_frame_id());
    return out + "]}";
}

// A generated type registered on the participant, refused unless its name is rmw_fastrtps's.
static bool register_as_rmw(DomainParticipant* participant, TypeSupport& type, const std::string& package,
                            const std::string& name) {
    const std::string wanted = rmw_type_name(package, name);
    if (type.get_type_name() != wanted) {
        std::fprintf(stderr, "generated type %s is not named %s as rmw_fastrtps names it\n",
                     type.get_type_name().c_str(), wanted.c_str());
        return false;
    }
    return type.register_type(participant) == ReturnCode_t::RETCODE_OK;
}

// Takes one sample of the generated type T and prints it: 1, a sample printed; 0, no data in it; -1, none left.
template <typename T>
static int take_one(DataReader* reader, FILE* out) {
    T sample;
    SampleInfo info;
    if (reader->take_next_sample(&sample, &info) != ReturnCode_t::RETCODE_OK) return -1;
    if (!info.valid_data) return 0;
    std::fprintf(out, "%s\n", as_json(sample).c_str());
    return 1;
}

int main(int argc, char** argv) {
    if (argc != 6) {
        std::fprintf(stderr, "usage: %s DOMAIN OUT.jsonl LINEAR_X ANGULAR_Z MAX_WALL_S\n", argv[0]);
        return 2;
    }
    const int domain = std::atoi(argv[1]);
    FILE* out = std::fopen(argv[2], "w");
    const double vx = std::atof(argv[3]), wz = std::atof(argv[4]), max_wall_s = std::atof(argv[5]);
    if (out == nullptr) return 2;

    DomainParticipant* participant =
        DomainParticipantFactory::get_instance()->create_participant(domain, PARTICIPANT_QOS_DEFAULT);
    if (participant == nullptr) return 3;
    Subscriber* subscriber = participant->create_subscriber(SUBSCRIBER_QOS_DEFAULT);
    Publisher* publisher = participant->create_publisher(PUBLISHER_QOS_DEFAULT);

    DataReaderQos reader_qos = DATAREADER_QOS_DEFAULT;
    reader_qos.reliability().kind = BEST_EFFORT_RELIABILITY_QOS;
    reader_qos.durability().kind = VOLATILE_DURABILITY_QOS;
    reader_qos.history().kind = KEEP_LAST_HISTORY_QOS;
    reader_qos.history().depth = 100;
    // As rmw_fastrtps sets its readers and writers: a generated type's preallocated size assumes at most
    // 100 elements in an unbounded sequence, so a 360-ray scan needs history that may grow.
    reader_qos.endpoint().history_memory_policy = eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
    reader_qos.data_sharing().off();
    // Each subscription: the ROS 2 topic, its message (package, name), the generated type, how to take it.
    struct Input {
        const char* name;
        const char* package;
        const char* message;
        TypeSupport type;
        std::function<int(DataReader*, FILE*)> take_one;
        DataReader* reader;
    };
    std::vector<Input> inputs = {
        {"/scan", "sensor_msgs", "LaserScan", TypeSupport(new sensor_msgs::msg::LaserScanPubSubType()),
         take_one<sensor_msgs::msg::LaserScan>, nullptr},
        {"/odom", "nav_msgs", "Odometry", TypeSupport(new nav_msgs::msg::OdometryPubSubType()),
         take_one<nav_msgs::msg::Odometry>, nullptr},
        {"/clock", "rosgraph_msgs", "Clock", TypeSupport(new rosgraph_msgs::msg::ClockPubSubType()),
         take_one<rosgraph_msgs::msg::Clock>, nullptr},
        {"/tf", "tf2_msgs", "TFMessage", TypeSupport(new tf2_msgs::msg::TFMessagePubSubType()),
         take_one<tf2_msgs::msg::TFMessage>, nullptr},
    };
    for (Input& in : inputs) {
        if (!register_as_rmw(participant, in.type, in.package, in.message)) return 5;
        const std::string topic_name = std::string("rt") + in.name;
        Topic* topic = participant->create_topic(topic_name, in.type.get_type_name(), TOPIC_QOS_DEFAULT);
        in.reader = topic == nullptr ? nullptr : subscriber->create_datareader(topic, reader_qos);
        if (in.reader == nullptr) return 4;
    }
    TypeSupport twist_type(new geometry_msgs::msg::TwistPubSubType());
    if (!register_as_rmw(participant, twist_type, "geometry_msgs", "Twist")) return 5;
    Topic* cmd_topic = participant->create_topic("rt/cmd_vel", twist_type.get_type_name(), TOPIC_QOS_DEFAULT);
    if (cmd_topic == nullptr) return 4;
    DataWriterQos writer_qos = DATAWRITER_QOS_DEFAULT;
    writer_qos.reliability().kind = RELIABLE_RELIABILITY_QOS;
    writer_qos.durability().kind = VOLATILE_DURABILITY_QOS;
    writer_qos.history().kind = KEEP_LAST_HISTORY_QOS;
    writer_qos.history().depth = 10;
    writer_qos.endpoint().history_memory_policy = eprosima::fastrtps::rtps::PREALLOCATED_WITH_REALLOC_MEMORY_MODE;
    writer_qos.data_sharing().off();
    DataWriter* writer = publisher->create_datawriter(cmd_topic, writer_qos);
    if (writer == nullptr) return 4;
    geometry_msgs::msg::Twist command;
    command.linear().x(vx);
    command.angular().z(wz);

    using clock = std::chrono::steady_clock;
    const auto start = clock::now();
    auto last_clock = clock::now(), next_cmd = clock::now();
    bool heard_clock = false;
    long sent = 0;
    while (true) {
        const auto now = clock::now();
        if (std::chrono::duration<double>(now - start).count() > max_wall_s) break;
        if (heard_clock && std::chrono::duration<double>(now - last_clock).count() > 3.0) break;
        if (now >= next_cmd) {
            if (writer->write(&command)) ++sent;
            next_cmd += std::chrono::milliseconds(100);
        }
        for (Input& in : inputs) {
            for (int got; (got = in.take_one(in.reader, out)) >= 0;) {
                if (got == 1 && std::string(in.name) == "/clock") {
                    heard_clock = true;
                    last_clock = clock::now();
                }
            }
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
    }
    std::fprintf(out, "{\"sent_cmd_vel\": %ld}\n", sent);
    std::fclose(out);
    participant->delete_contained_entities();
    DomainParticipantFactory::get_instance()->delete_participant(participant);
    return 0;
}
