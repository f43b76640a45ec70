// pantilt_servo.ino - the pan-tilt calibration device on an Arduino (wingphoto pantilt --backend serial
// --protocol arduino). Drives the pan servo (HS-311) and the tilt servo (S03N) with 50 Hz pulse trains
// and an optional camera trigger line, on commands from the serial port (9600 baud, one line each):
//
//   H                     hello; answers OK when ready
//   W <pan_us> <tilt_us>  set the pulse widths in microseconds (e.g. "W 1300 2000"); answers OK
//   T <0|1>               camera trigger line low / high (TTL); answers OK
//
// Anything else, or a width outside 500..2500 us, answers "ERR <reason>". Wiring: pan servo signal on
// pin 9, tilt servo signal on pin 10, trigger on pin 7 (change the constants below), servo power from a
// separate 5-6 V supply with its ground joined to the Arduino's.
#include <Servo.h>

const int PAN_PIN = 9;
const int TILT_PIN = 10;
const int TRIGGER_PIN = 7;

Servo pan;
Servo tilt;
char line[40];
int len = 0;

void setup() {
  Serial.begin(9600);
  pinMode(TRIGGER_PIN, OUTPUT);
  digitalWrite(TRIGGER_PIN, LOW);
  tilt.attach(TILT_PIN);
  tilt.writeMicroseconds(1500);   // neutral until told otherwise
  pan.attach(PAN_PIN);
  pan.writeMicroseconds(1500);
}

void handle(char *cmd) {
  long a, b;
  if (cmd[0] == 'H') {
    Serial.println("OK");
  } else if (cmd[0] == 'W' && sscanf(cmd + 1, "%ld %ld", &a, &b) == 2) {
    if (a < 500 || a > 2500 || b < 500 || b > 2500) {
      Serial.println("ERR range");
      return;
    }
    tilt.writeMicroseconds((int)b);
    pan.writeMicroseconds((int)a);
    Serial.println("OK");
  } else if (cmd[0] == 'T' && sscanf(cmd + 1, "%ld", &a) == 1) {
    digitalWrite(TRIGGER_PIN, a ? HIGH : LOW);
    Serial.println("OK");
  } else {
    Serial.println("ERR command");
  }
}

void loop() {
  while (Serial.available() > 0) {
    char c = Serial.read();
    if (c == '\r') continue;
    if (c == '\n') {
      line[len] = '\0';
      if (len > 0) handle(line);
      len = 0;
    } else if (len < (int)sizeof(line) - 1) {
      line[len++] = c;
    }
  }
}
