// A ROS 2 peer built on eProsima Fast DDS (ROS 2 Humble's default middleware), independent of the twin.
//
// It joins a DDS domain as rmw_fastrtps would: topics `rt/<name>`, types named as rosidl names them
// (`sensor_msgs::msg::dds_::LaserScan_`), payloads in plain little-endian CDR decoded here with Fast
// CDR, field by field, as the ROS 2 message definitions lay them out. It reads /scan, /odom, /clock
// and /tf (best effort: what a sensor-data subscriber asks) and publishes /cmd_vel (reliable, as
// `rclcpp::QoS(10)` does) at 10 Hz. It ends when /clock has been silent for 3 s after it started, or at
// the wall-time limit, and writes what it received as JSON lines.
//
// usage: fastdds_peer DOMAIN OUT.jsonl LINEAR_X ANGULAR_Z MAX_WALL_S

#include <fastcdr/Cdr.h>
#include <fastcdr/FastBuffer.h>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <thread>
#include <vector>

using namespace eprosima::fastdds::dds;
using eprosima::fastcdr::Cdr;
using eprosima::fastcdr::FastBuffer;
using eprosima::fastrtps::rtps::InstanceHandle_t;
using eprosima::fastrtps::rtps::SerializedPayload_t;

// A sample is its serialized payload, encapsulation header included: decoded and encoded by hand below.
struct Raw {
    std::vector<unsigned char> bytes;
};

class RawType : public TopicDataType {
  public:
    explicit RawType(const char* name) {
        setName(name);
        m_typeSize = 1 << 18;
        m_isGetKeyDefined = false;
    }
    bool serialize(void* data, SerializedPayload_t* payload) override {
        auto* raw = static_cast<Raw*>(data);
        if (raw->bytes.size() > payload->max_size) return false;
        std::memcpy(payload->data, raw->bytes.data(), raw->bytes.size());
        payload->length = static_cast<uint32_t>(raw->bytes.size());
        payload->encapsulation = CDR_LE;
        return true;
    }
    bool deserialize(SerializedPayload_t* payload, void* data) override {
        static_cast<Raw*>(data)->bytes.assign(payload->data, payload->data + payload->length);
        return true;
    }
    std::function<uint32_t()> getSerializedSizeProvider(void* data) override {
        return [data]() { return static_cast<uint32_t>(static_cast<Raw*>(data)->bytes.size()); };
    }
    void* createData() override { return new Raw(); }
    void deleteData(void* data) override { delete static_cast<Raw*>(data); }
    bool getKey(void*, InstanceHandle_t*, bool) override { return false; }
};

struct Stamp {
    int32_t sec;
    uint32_t nanosec;
    std::string frame_id;
};

static Stamp read_header(Cdr& cdr) {
    Stamp h{};
    cdr >> h.sec >> h.nanosec >> h.frame_id;
    return h;
}

// A number as JSON (Python's reader): Infinity, -Infinity and NaN for the non-finite (a lidar's "no return").
static std::string number(double v, bool single) {
    if (std::isnan(v)) return "NaN";
    if (std::isinf(v)) return v > 0 ? "Infinity" : "-Infinity";
    char num[64];
    std::snprintf(num, sizeof num, single ? "%.9g" : "%.17g", v);
    return num;
}

static std::string decode(const std::string& topic, Raw& raw) {
    FastBuffer buffer(reinterpret_cast<char*>(raw.bytes.data()), raw.bytes.size());
    Cdr cdr(buffer, Cdr::DEFAULT_ENDIAN, Cdr::DDS_CDR);
    cdr.read_encapsulation();
    std::string out = "{\"topic\": \"" + topic + "\"";
    auto add = [&](const char* key, double v, bool single) {
        out += std::string(", \"") + key + "\": " + number(v, single);
    };
    if (topic == "/clock") {
        int32_t sec;
        uint32_t nanosec;
        cdr >> sec >> nanosec;
        out += ", \"sec\": " + std::to_string(sec) + ", \"nanosec\": " + std::to_string(nanosec);
    } else if (topic == "/scan") {
        Stamp h = read_header(cdr);
        float f[7];
        for (float& x : f) cdr >> x;
        std::vector<float> ranges, intensities;
        cdr >> ranges >> intensities;
        out += ", \"sec\": " + std::to_string(h.sec) + ", \"nanosec\": " + std::to_string(h.nanosec);
        out += ", \"frame_id\": \"" + h.frame_id + "\"";
        add("angle_min", f[0], true);
        add("angle_max", f[1], true);
        add("range_max", f[6], true);
        out += ", \"ranges\": [";
        for (size_t i = 0; i < ranges.size(); ++i) out += (i ? ", " : "") + number(ranges[i], true);
        out += "]";
    } else if (topic == "/odom") {
        Stamp h = read_header(cdr);
        std::string child;
        cdr >> child;
        double pose[7], cov[36], twist[6];
        for (double& x : pose) cdr >> x;
        cdr.deserializeArray(cov, 36);
        for (double& x : twist) cdr >> x;
        out += ", \"sec\": " + std::to_string(h.sec) + ", \"nanosec\": " + std::to_string(h.nanosec);
        out += ", \"frame_id\": \"" + h.frame_id + "\", \"child_frame_id\": \"" + child + "\"";
        add("x", pose[0], false);
        add("y", pose[1], false);
        add("vx", twist[0], false);
    } else if (topic == "/tf") {
        uint32_t n;
        cdr >> n;
        out += ", \"children\": [";
        for (uint32_t i = 0; i < n; ++i) {
            Stamp h = read_header(cdr);
            std::string child;
            cdr >> child;
            double t[7];
            for (double& x : t) cdr >> x;
            out += std::string(i ? ", " : "") + "\"" + child + "\"";
        }
        out += "]";
    }
    return out + "}";
}

static Raw twist(double vx, double wz) {
    char buf[64];
    FastBuffer buffer(buf, sizeof buf);
    Cdr cdr(buffer, Cdr::DEFAULT_ENDIAN, Cdr::DDS_CDR);
    cdr.serialize_encapsulation();
    cdr << vx << 0.0 << 0.0 << 0.0 << 0.0 << wz;
    Raw raw;
    raw.bytes.assign(buf, buf + cdr.getSerializedDataLength());
    return raw;
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

    struct In {
        std::string name;
        const char* type;
        DataReader* reader;
    };
    std::vector<In> inputs = {
        {"/scan", "sensor_msgs::msg::dds_::LaserScan_", nullptr},
        {"/odom", "nav_msgs::msg::dds_::Odometry_", nullptr},
        {"/clock", "rosgraph_msgs::msg::dds_::Clock_", nullptr},
        {"/tf", "tf2_msgs::msg::dds_::TFMessage_", nullptr},
    };
    DataReaderQos reader_qos = DATAREADER_QOS_DEFAULT;
    reader_qos.reliability().kind = BEST_EFFORT_RELIABILITY_QOS;
    reader_qos.durability().kind = VOLATILE_DURABILITY_QOS;
    reader_qos.history().kind = KEEP_LAST_HISTORY_QOS;
    reader_qos.history().depth = 100;
    for (In& in : inputs) {
        TypeSupport type(new RawType(in.type));
        type.register_type(participant);
        Topic* topic = participant->create_topic("rt" + in.name, in.type, TOPIC_QOS_DEFAULT);
        in.reader = subscriber->create_datareader(topic, reader_qos);
        if (in.reader == nullptr) return 4;
    }
    TypeSupport twist_type(new RawType("geometry_msgs::msg::dds_::Twist_"));
    twist_type.register_type(participant);
    Topic* cmd_topic = participant->create_topic("rt/cmd_vel", "geometry_msgs::msg::dds_::Twist_", TOPIC_QOS_DEFAULT);
    DataWriterQos writer_qos = DATAWRITER_QOS_DEFAULT;
    writer_qos.reliability().kind = RELIABLE_RELIABILITY_QOS;
    writer_qos.durability().kind = VOLATILE_DURABILITY_QOS;
    writer_qos.history().kind = KEEP_LAST_HISTORY_QOS;
    writer_qos.history().depth = 10;
    DataWriter* writer = publisher->create_datawriter(cmd_topic, writer_qos);
    if (writer == nullptr) return 4;

    using clock = std::chrono::steady_clock;
    const auto start = clock::now();
    auto last_clock = clock::now(), next_cmd = clock::now();
    bool heard_clock = false;
    long sent = 0;
    Raw sample, command = twist(vx, wz);
    SampleInfo info;
    while (true) {
        const auto now = clock::now();
        if (std::chrono::duration<double>(now - start).count() > max_wall_s) break;
        if (heard_clock && std::chrono::duration<double>(now - last_clock).count() > 3.0) break;
        if (now >= next_cmd) {
            if (writer->write(&command)) ++sent;
            next_cmd += std::chrono::milliseconds(100);
        }
        for (In& in : inputs) {
            while (in.reader->take_next_sample(&sample, &info) == ReturnCode_t::RETCODE_OK) {
                if (!info.valid_data) continue;
                if (in.name == "/clock") {
                    heard_clock = true;
                    last_clock = clock::now();
                }
                std::fprintf(out, "%s\n", decode(in.name, sample).c_str());
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
